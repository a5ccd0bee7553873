/* CLIP's text tokenizer (OpenAI's simple_tokenizer.py), in C: byte-level BPE over the merges
 * of OpenAI's bpe_simple_vocab_16e6.txt.gz (gzip) or a Hugging Face merges.txt (plain text,
 * first line "#version: ..."), 48,894 merges either way.
 *
 * Vocabulary: ids 0-255 are the 256 byte symbols in bytes_to_unicode order, 256-511 the same
 * with "</w>", 512 + k the result of merge k, then <|startoftext|> (49406) and
 * <|endoftext|> (49407) for the full file.
 *
 * Text is cleaned as OpenAI does, except for ftfy.fix_text, which this port leaves out (see
 * tokenizer.c for that and for the HTML entities it knows): HTML character references are
 * un-escaped twice, runs of whitespace become one space, leading and trailing whitespace go,
 * and it is lower-cased as Python's str.lower. It is then split by CLIP's pattern
 *   <\|startoftext\|>|<\|endoftext\|>|'s|'t|'re|'ve|'m|'ll|'d|[\p{L}]+|[\p{N}]|[^\s\p{L}\p{N}]+
 * (PCRE2, UTF mode), each piece's UTF-8 bytes mapped to byte symbols, the last one marked
 * with </w>, and merged by rank. Invalid UTF-8 is FG_EINVAL.
 *
 * A loaded tokenizer is immutable: it may be shared by threads. */
#ifndef FG_CLIP_TOKENIZER_H
#define FG_CLIP_TOKENIZER_H

#include <stddef.h>
#include <stdint.h>

#define FG_TOKEN_SOT 49406
#define FG_TOKEN_EOT 49407

typedef struct fg_tokenizer fg_tokenizer;

/* Loads a merges file (gzip or plain, told apart by its magic). On success the caller owns
 * *out (fg_tokenizer_free); on failure *out is NULL and the detail says what was wrong
 * (FG_ENOENT, FG_EIO, or FG_EFORMAT for a truncated or malformed file, naming the line;
 * FG_EFORMAT too for fewer than 48,894 merges and for a gzip unpacking to over 16 MB). */
int fg_tokenizer_load(fg_tokenizer **out, const char *path);

/* Same from an in-memory file of len bytes (gzip or plain); buf is only read. */
int fg_tokenizer_load_buffer(fg_tokenizer **out, const void *buf, size_t len);

/* Frees tok; NULL is fine. */
void fg_tokenizer_free(fg_tokenizer *tok);

/* Vocabulary size (49408 for the full merges file). */
int fg_tokenizer_vocab_size(const fg_tokenizer *tok);

/* BPE ids of text without start/end tokens, as OpenAI's SimpleTokenizer.encode: writes at
 * most max ids to ids (caller-owned) and the total count to *n (which may exceed max; then
 * only the first max are written; ids may be NULL when max is 0). 0, FG_EINVAL (invalid
 * UTF-8, with the byte offset), FG_ENOMEM. */
int fg_tokenizer_bpe(const fg_tokenizer *tok, const char *text, int32_t *ids, size_t max,
                     size_t *n);

/* A model input as OpenAI's clip.tokenize: ids [context] = start, BPE ids, end, zeros.
 * When start + tokens + end exceed context: FG_ERANGE ("... is N tokens, the limit is
 * context - 2") unless truncate is set, in which case the ids are cut and the last one is
 * the end token. *n_tokens (may be NULL) receives the count written before the zero
 * padding. context must be at least 2 (FG_EINVAL otherwise); on any error ids[0, context)
 * are all zero and *n_tokens is 0. */
int fg_tokenizer_encode(const fg_tokenizer *tok, const char *text, int context, int truncate,
                        int32_t *ids, int *n_tokens);

/* Decodes ids back to text (the inverse of bpe for tests and logs): "</w>" becomes a space,
 * start/end tokens are dropped, bytes that do not form UTF-8 become U+FFFD (as Python's
 * errors="replace"). Returns a malloc'd string the caller frees, or NULL on an id outside
 * the vocabulary (with a detail) or out of memory. */
char *fg_tokenizer_decode(const fg_tokenizer *tok, const int32_t *ids, size_t n);

#endif
