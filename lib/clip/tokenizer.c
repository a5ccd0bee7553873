/* CLIP's text tokenizer: a port of OpenAI's simple_tokenizer.py (SimpleTokenizer) and of
 * clip.tokenize, checked id for id against the Python reference (tests/clip).
 *
 * Loading reads the merges (gzip by magic 1f 8b, unpacked with zlib under a 16 MB cap, or a
 * plain merges.txt whose first line starts with "#version"), lays out the text of every
 * vocabulary symbol and builds one open-addressing table from a pair of symbol ids to the
 * merge's rank and the merged symbol's id. Symbol strings exist only at load time and for
 * decode; BPE itself works on integer ids.
 *
 * Text goes through the reference's steps in order:
 *   1. ftfy.fix_text: LEFT OUT. ftfy is not packaged for Debian, and on text that is already
 *      clean NFC Unicode it changes nothing. Text with mojibake ("cafÃ©"), decomposed accents
 *      (NFD "cafe\u0301") or other things ftfy repairs is tokenized as it stands, where the
 *      reference would first repair (and NFC-compose) it.
 *   2. html.unescape, twice. Numeric references follow Python exactly (windows-1252 for
 *      0x80-0x9f, U+FFFD for 0, surrogates and values past U+10FFFF, nothing for the
 *      noncharacters and most C0/C1 controls). Named references: the 252 HTML 4 entities plus
 *      apos and the upper-case spellings AMP, COPY, GT, LT, QUOT, REG. That includes every
 *      name HTML 5 accepts without a semicolon, so the longest-prefix rule ("&ampx" -> "&x",
 *      "&notit;" -> "¬it;") is exact; the other ~2,000 HTML 5 names (&NewLine;, &bigstar;)
 *      are left as they are.
 *   3. strip (str.isspace), runs of \s (the White_Space property, as the regex module) to one
 *      space. The second strip of the reference has nothing left to remove.
 *   4. str.lower: glibc's towlower_l in C.UTF-8 (the same simple mapping as Python for every
 *      code point), plus the two places where Python's full lower-casing differs: U+0130 İ
 *      becomes "i" U+0307, and Σ becomes final ς by Python's Final_Sigma rule (cased letter,
 *      case-ignorables, Σ, no cased letter after), with PCRE2's \p{Cased} and
 *      \p{Case_Ignorable}.
 *   5. The split pattern. The reference compiles it with re.IGNORECASE, which on lower-cased
 *      text still matters in two places that the pattern here spells out: 's also matches 'ſ
 *      (U+017F folds to s; likewise <|ſtartoftext|> is one piece, though not a special
 *      token), and U+0345 (which folds to ι) is matched by no branch, so it only separates
 *      pieces. \s inside the last class is a plain space: step 3 left no other White_Space,
 *      and PCRE2's \s would also take U+180E, which the regex module does not. Letters and digits are PCRE2's \p{L} and \p{N}; the regex module may know
 *      a newer Unicode version, and characters added since tokenize differently.
 *   6. Each piece's UTF-8 bytes become byte symbols, the last with "</w>", and the adjacent
 *      pair of lowest rank is merged, every occurrence left to right in one pass, until no
 *      pair has a rank: the reference's bpe() step for step, including its quadratic cost in
 *      the length of one piece. */
#define PCRE2_CODE_UNIT_WIDTH 8

#include "clip/tokenizer.h"
#include "clip/text_clean.h"
#include "core/error.h"
#include "core/fsutil.h"

#include <locale.h>
#include <pcre2.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <wctype.h>
#include <zlib.h>

#define N_MERGES 48894                    /* merges[1:49152-256-2+1] of the reference */
#define VOCAB_SIZE (2 * 256 + N_MERGES + 2) /* 49408 */
#define MAX_FILE_BYTES (64u << 20)        /* a merges file on disk */
#define MAX_UNPACKED_BYTES (16u << 20)    /* the gzip file unpacked (3.2 MB for OpenAI's) */
#define PAIR_BITS 17                      /* 131072 slots for 48894 merges */
#define PAIR_MASK ((1u << PAIR_BITS) - 1)
#define PAIR_EMPTY 0xFFFFFFFFu
#define NO_RANK INT32_MAX

static const char SOT_TEXT[] = "<|startoftext|>";
static const char EOT_TEXT[] = "<|endoftext|>";
static const char EOW[] = "</w>";

/* The split pattern of the reference, with IGNORECASE's effects written out (see above). */
static const char SPLIT_PATTERN[] =
    "<\\|[s\\x{17f}]tartoftext\\|>|<\\|endoftext\\|>|'[s\\x{17f}]|'t|'re|'ve|'m|'ll|'d"
    "|\\p{L}+|\\p{N}|[^ \\p{L}\\p{N}\\x{345}]+";

/* One merge: the pair (left id, right id) packed in key. */
typedef struct pair_slot {
  uint32_t key;   /* left << 16 | right; PAIR_EMPTY when the slot is free */
  int32_t rank;   /* merge index in the file: lower ranks merge first */
  int32_t merged; /* id of the merged symbol */
} pair_slot;

struct fg_tokenizer {
  pair_slot *pairs;          /* [1 << PAIR_BITS], owned */
  int32_t byte_id[256];      /* raw byte -> id of its symbol */
  int32_t byte_eow_id[256];  /* raw byte -> id of its symbol + "</w>" */
  uint8_t unicode_byte[324]; /* bytes_to_unicode inverse: code point (< 324) -> raw byte */
  char *text;                /* owned: every symbol's text (bytes_to_unicode UTF-8) back to back */
  uint32_t *text_off;        /* [VOCAB_SIZE + 1], owned: id's text is text[off[id], off[id + 1]) */
  pcre2_code *pattern;       /* SPLIT_PATTERN, shared read-only by all threads */
  pcre2_code *cased;         /* \p{Cased} and \p{Case_Ignorable}, for the final sigma */
  pcre2_code *case_ignorable;
  locale_t ctype; /* C.UTF-8 for towlower_l: no change to the process's locale */
};

/* ---- lower case ----------------------------------------------------------------------- */

/* Whether c has the property of re (an anchored single-property pattern). */
static int has_property(const pcre2_code *re, pcre2_match_data *md, uint32_t c) {
  uint8_t buf[4];
  size_t len = fg_clip_utf8_put(buf, c);
  return pcre2_match(re, buf, len, 0, PCRE2_ANCHORED | PCRE2_NO_UTF_CHECK, md, NULL) > 0;
}

/* Python's Final_Sigma test for the capital sigma at c[i]: a cased letter before it and
 * none after it, case-ignorable characters skipped both ways. */
static int is_final_sigma(const fg_tokenizer *tok, pcre2_match_data *md, const uint32_t *c,
                          size_t n, size_t i) {
  size_t j = i;
  while (j > 0 && has_property(tok->case_ignorable, md, c[j - 1])) j--;
  if (j == 0 || !has_property(tok->cased, md, c[j - 1])) return 0;
  for (j = i + 1; j < n && has_property(tok->case_ignorable, md, c[j]); j++) {
  }
  return j == n || !has_property(tok->cased, md, c[j]);
}

/* str.lower of c[0, n) into out (room for 2 * n: U+0130 becomes two code points); *n_out
 * receives the length. */
static int lower_text(const fg_tokenizer *tok, const uint32_t *c, size_t n, uint32_t *out,
                      size_t *n_out) {
  pcre2_match_data *md = NULL;
  size_t w = 0;
  for (size_t i = 0; i < n; i++) {
    uint32_t ch = c[i];
    if (ch < 0x80) {
      out[w++] = ch >= 'A' && ch <= 'Z' ? ch + 32 : ch;
    } else if (ch == 0x130) {
      out[w++] = 'i';
      out[w++] = 0x307;
    } else if (ch == 0x3A3) {
      if (!md && !(md = pcre2_match_data_create(1, NULL)))
        return fg_fail(FG_ENOMEM, "out of memory lower-casing the text");
      out[w++] = is_final_sigma(tok, md, c, n, i) ? 0x3C2 : 0x3C3;
    } else {
      out[w++] = (uint32_t)towlower_l((wint_t)ch, tok->ctype);
    }
  }
  pcre2_match_data_free(md);
  *n_out = w;
  return 0;
}

/* ---- the merges file ------------------------------------------------------------------ */

/* bytes_to_unicode's printable bytes, which stand for themselves. */
static int byte_printable(int b) {
  return (b >= '!' && b <= '~') || (b >= 0xA1 && b <= 0xAC) || (b >= 0xAE && b <= 0xFF);
}

/* Unpacks a gzip file (all its members) into a malloc'd, NUL-terminated buffer the caller
 * owns; more than MAX_UNPACKED_BYTES is refused, so a gzip bomb is an error, not an OOM. */
static int gunzip(const uint8_t *in, size_t len, char **out, size_t *out_len) {
  *out = NULL;
  z_stream zs;
  memset(&zs, 0, sizeof zs);
  if (inflateInit2(&zs, 16 + MAX_WBITS) != Z_OK)
    return fg_fail(FG_ENOMEM, "out of memory starting to unpack the merges file");
  size_t cap = len < (MAX_UNPACKED_BYTES / 4) ? 4 * len + 4096 : MAX_UNPACKED_BYTES;
  char *buf = malloc(cap + 1);
  int rc = 0;
  if (!buf) {
    rc = fg_fail(FG_ENOMEM, "out of memory unpacking the merges file");
    goto done;
  }
  zs.next_in = (Bytef *)(uintptr_t)in;
  zs.avail_in = (uInt)len;
  size_t used = 0;
  for (;;) {
    if (used == cap) {
      if (cap >= MAX_UNPACKED_BYTES) {
        rc = fg_fail(FG_EFORMAT, "the gzip merges file unpacks to more than %u MB",
                     MAX_UNPACKED_BYTES >> 20);
        goto done;
      }
      size_t ncap = 2 * cap < MAX_UNPACKED_BYTES ? 2 * cap : MAX_UNPACKED_BYTES;
      char *nbuf = realloc(buf, ncap + 1);
      if (!nbuf) {
        rc = fg_fail(FG_ENOMEM, "out of memory unpacking the merges file");
        goto done;
      }
      buf = nbuf;
      cap = ncap;
    }
    zs.next_out = (Bytef *)buf + used;
    zs.avail_out = (uInt)(cap - used);
    int z = inflate(&zs, Z_NO_FLUSH);
    used = cap - zs.avail_out;
    if (z == Z_STREAM_END) {
      while (zs.avail_in > 0 && zs.next_in[0] == 0) { /* zero padding after a member */
        zs.next_in++;
        zs.avail_in--;
      }
      if (zs.avail_in == 0) break;
      if (zs.avail_in < 2 || zs.next_in[0] != 0x1f || zs.next_in[1] != 0x8b) {
        rc = fg_fail(FG_EFORMAT, "the gzip merges file has %u bytes of trailing garbage",
                     zs.avail_in);
        goto done;
      }
      inflateReset(&zs); /* another member follows, as gzip -c a b > ab writes */
    } else if (z == Z_OK || z == Z_BUF_ERROR) {
      if (zs.avail_out > 0 && zs.avail_in == 0) {
        rc = fg_fail(FG_EFORMAT, "the gzip merges file is truncated (it ends after %zu "
                                 "unpacked bytes)", used);
        goto done;
      }
    } else if (z == Z_MEM_ERROR) {
      rc = fg_fail(FG_ENOMEM, "out of memory unpacking the merges file");
      goto done;
    } else {
      rc = fg_fail(FG_EFORMAT, "the gzip merges file is corrupt: %s",
                   zs.msg ? zs.msg : "invalid deflate data");
      goto done;
    }
  }
  buf[used] = '\0';
  *out = buf;
  *out_len = used;
  buf = NULL;
done:
  inflateEnd(&zs);
  free(buf);
  return rc;
}

/* Load-time map from a symbol's text to the first and last id with that text. The
 * reference keys its vocabulary by string, so should two merges spell the same symbol the
 * later id is the one it uses (dict semantics); OpenAI's file has no such duplicates. */
typedef struct str_slot {
  int32_t first, last; /* -1 when free */
} str_slot;

typedef struct str_map {
  str_slot *slots; /* [1 << PAIR_BITS] */
  const char *text;
  const uint32_t *off;
} str_map;

static uint32_t str_hash(const char *s, size_t len) {
  uint32_t h = 2166136261u; /* FNV-1a */
  for (size_t i = 0; i < len; i++) h = (h ^ (uint8_t)s[i]) * 16777619u;
  return h;
}

/* The slot of s[0, len), or the free slot where it would go. */
static str_slot *str_map_slot(const str_map *m, const char *s, size_t len) {
  for (uint32_t i = str_hash(s, len) & PAIR_MASK;; i = (i + 1) & PAIR_MASK) {
    str_slot *sl = &m->slots[i];
    if (sl->first < 0) return sl;
    uint32_t a = m->off[sl->first], b = m->off[sl->first + 1];
    if (b - a == len && memcmp(m->text + a, s, len) == 0) return sl;
  }
}

/* The slot of merge pair (a, b), or the free slot where it would go. */
static pair_slot *pair_slot_of(pair_slot *pairs, uint32_t key) {
  for (uint32_t i = (key * 2654435761u) >> (32 - PAIR_BITS);; i = (i + 1) & PAIR_MASK) {
    if (pairs[i].key == key || pairs[i].key == PAIR_EMPTY) return &pairs[i];
  }
}

/* Splits the merge lines of data[0, len) (line 1 is a header; merges are lines 2 ..
 * N_MERGES + 1, each "a b"): merge k's text a b is written to text from off[512 + k], which
 * the caller has set, and off[512 + k + 1] is set after it; msplit[k] receives the length of
 * a. Lines past N_MERGES + 1 are ignored, as the reference does. */
static int parse_merges(const char *data, size_t len, char *text, uint32_t *off,
                        uint16_t *msplit) {
  const char *end = data + len, *p = memchr(data, '\n', len);
  size_t lines = 0; /* merge lines present: a final newline ends a line, it starts none */
  for (const char *q = p ? p + 1 : end; q < end && lines < N_MERGES; lines++) {
    const char *nl = memchr(q, '\n', (size_t)(end - q));
    q = nl ? nl + 1 : end;
  }
  if (lines < N_MERGES)
    return fg_fail(FG_EFORMAT, "the merges file has %zu merges, CLIP needs %d", lines,
                   N_MERGES);
  uint32_t t = off[512];
  p++;
  for (int k = 0; k < N_MERGES; k++) {
    const char *nl = memchr(p, '\n', (size_t)(end - p));
    const char *le = nl ? nl : end;
    if (le > p && le[-1] == '\r') le--; /* a merges.txt written on Windows */
    const char *sp = memchr(p, ' ', (size_t)(le - p));
    if (!sp || sp == p || sp + 1 == le || memchr(sp + 1, ' ', (size_t)(le - sp - 1)) ||
        sp - p > 0xFFFF)
      return fg_fail(FG_EFORMAT,
                     "line %d of the merges file is not two symbols separated by one space",
                     k + 2);
    msplit[k] = (uint16_t)(sp - p);
    memcpy(text + t, p, (size_t)(sp - p));
    t += (uint32_t)(sp - p);
    memcpy(text + t, sp + 1, (size_t)(le - sp - 1));
    t += (uint32_t)(le - sp - 1);
    off[512 + k + 1] = t;
    p = nl ? nl + 1 : end;
  }
  return 0;
}

/* Builds the vocabulary and the merge table of tok from the unpacked file data[0, len). */
static int build_tables(fg_tokenizer *tok, const char *data, size_t len) {
  uint8_t bs[256];
  uint32_t cs[256];
  int n = 0, extra = 0;
  for (int b = 0; b < 256; b++)
    if (byte_printable(b)) bs[n] = (uint8_t)b, cs[n++] = (uint32_t)b;
  for (int b = 0; b < 256; b++)
    if (!byte_printable(b)) bs[n] = (uint8_t)b, cs[n++] = 256u + (uint32_t)extra++;
  for (int i = 0; i < 256; i++) tok->unicode_byte[cs[i]] = bs[i];

  /* Text of every symbol: bytes, bytes + "</w>", merges, then the two special tokens. */
  tok->text = malloc(256 * 8 + len + sizeof SOT_TEXT + sizeof EOT_TEXT);
  tok->text_off = malloc((VOCAB_SIZE + 1) * sizeof *tok->text_off);
  uint16_t *msplit = malloc(N_MERGES * sizeof *msplit);
  str_map m = {calloc(1u << PAIR_BITS, sizeof(str_slot)), tok->text, tok->text_off};
  tok->pairs = malloc((1u << PAIR_BITS) * sizeof *tok->pairs);
  int rc = 0;
  if (!tok->text || !tok->text_off || !msplit || !m.slots || !tok->pairs) {
    rc = fg_fail(FG_ENOMEM, "out of memory building the tokenizer");
    goto done;
  }
  uint32_t *off = tok->text_off, t = 0;
  for (int i = 0; i < 512; i++) {
    off[i] = t;
    t += (uint32_t)fg_clip_utf8_put((uint8_t *)tok->text + t, cs[i & 255]);
    if (i >= 256) memcpy(tok->text + t, EOW, 4), t += 4;
  }
  off[512] = t;
  if ((rc = parse_merges(data, len, tok->text, off, msplit)) < 0) goto done;
  t = off[512 + N_MERGES];
  memcpy(tok->text + t, SOT_TEXT, strlen(SOT_TEXT));
  off[VOCAB_SIZE - 1] = t + (uint32_t)strlen(SOT_TEXT);
  memcpy(tok->text + off[VOCAB_SIZE - 1], EOT_TEXT, strlen(EOT_TEXT));
  off[VOCAB_SIZE] = off[VOCAB_SIZE - 1] + (uint32_t)strlen(EOT_TEXT);

  memset(m.slots, 0xFF, (1u << PAIR_BITS) * sizeof(str_slot)); /* first = last = -1 */
  for (int32_t id = 0; id < VOCAB_SIZE; id++) {
    str_slot *sl = str_map_slot(&m, tok->text + off[id], off[id + 1] - off[id]);
    if (sl->first < 0) sl->first = id;
    sl->last = id;
  }
  for (int i = 0; i < 256; i++) {
    tok->byte_id[bs[i]] = str_map_slot(&m, tok->text + off[i], off[i + 1] - off[i])->last;
    tok->byte_eow_id[bs[i]] =
        str_map_slot(&m, tok->text + off[256 + i], off[257 + i] - off[256 + i])->last;
  }

  memset(tok->pairs, 0xFF, (1u << PAIR_BITS) * sizeof *tok->pairs);
  for (int32_t k = 0; k < N_MERGES; k++) {
    int32_t id = 512 + k;
    const char *s = tok->text + off[id];
    size_t la = msplit[k], lb = off[id + 1] - off[id] - la;
    const str_slot *a = str_map_slot(&m, s, la), *b = str_map_slot(&m, s + la, lb);
    /* each part must be a symbol of an id below this merge's own */
    const str_slot *bad = a->first < 0 || a->first >= id   ? a
                          : b->first < 0 || b->first >= id ? b
                                                           : NULL;
    if (bad) {
      int bl = (int)(bad == a ? la : lb);
      rc = fg_fail(FG_EFORMAT,
                   "line %d of the merges file: \"%.*s\" is no symbol of the vocabulary the "
                   "lines before it built",
                   k + 2, bl > 64 ? 64 : bl, bad == a ? s : s + la);
      goto done;
    }
    pair_slot *p = pair_slot_of(tok->pairs, (uint32_t)a->last << 16 | (uint32_t)b->last);
    p->key = (uint32_t)a->last << 16 | (uint32_t)b->last;
    p->rank = k; /* a repeated pair keeps its last rank, as dict(zip(merges, range)) */
    p->merged = str_map_slot(&m, s, la + lb)->last;
  }
done:
  free(msplit);
  free(m.slots);
  return rc;
}

/* ---- load and free -------------------------------------------------------------------- */

void fg_tokenizer_free(fg_tokenizer *tok) {
  if (!tok) return;
  pcre2_code_free(tok->pattern);
  pcre2_code_free(tok->cased);
  pcre2_code_free(tok->case_ignorable);
  if (tok->ctype) freelocale(tok->ctype);
  free(tok->pairs);
  free(tok->text);
  free(tok->text_off);
  free(tok);
}

/* Compiles one pattern in UTF mode with Unicode properties; JIT when the platform has it. */
static int compile_pattern(pcre2_code **out, const char *pat) {
  int err;
  PCRE2_SIZE at;
  *out = pcre2_compile((PCRE2_SPTR)pat, PCRE2_ZERO_TERMINATED, PCRE2_UTF | PCRE2_UCP, &err, &at,
                       NULL);
  if (!*out) {
    PCRE2_UCHAR msg[160];
    pcre2_get_error_message(err, msg, sizeof msg);
    return fg_fail(err == PCRE2_ERROR_NOMEMORY ? FG_ENOMEM : FG_EINVAL,
                   "PCRE2 cannot compile the tokenizer pattern (offset %zu): %s", (size_t)at,
                   (const char *)msg);
  }
  pcre2_jit_compile(*out, PCRE2_JIT_COMPLETE); /* optional: the interpreter gives the same */
  return 0;
}

int fg_tokenizer_load_buffer(fg_tokenizer **out, const void *buf, size_t len) {
  if (!out) return fg_fail(FG_EINVAL, "fg_tokenizer_load_buffer: out is NULL");
  *out = NULL;
  if (!buf && len) return fg_fail(FG_EINVAL, "fg_tokenizer_load_buffer: buf is NULL");
  const uint8_t *b = buf;
  if (len == 0) return fg_fail(FG_EFORMAT, "the merges file is empty");
  if (len > MAX_FILE_BYTES)
    return fg_fail(FG_EFORMAT, "the merges file is %zu bytes, more than %u MB", len,
                   MAX_FILE_BYTES >> 20);
  char *unpacked = NULL;
  const char *data = buf;
  size_t dlen = len;
  if (len >= 2 && b[0] == 0x1f && b[1] == 0x8b) {
    FG_TRY(gunzip(b, len, &unpacked, &dlen));
    data = unpacked;
  } else if (len < 8 || memcmp(b, "#version", 8) != 0) {
    return fg_fail(FG_EFORMAT, "the merges file is neither gzip (magic 1f 8b) nor a "
                               "merges.txt whose first line starts with \"#version\"");
  }
  fg_tokenizer *tok = calloc(1, sizeof *tok);
  int rc = tok ? 0 : fg_fail(FG_ENOMEM, "out of memory allocating the tokenizer");
  if (rc == 0) rc = build_tables(tok, data, dlen);
  free(unpacked);
  if (rc == 0) rc = compile_pattern(&tok->pattern, SPLIT_PATTERN);
  if (rc == 0) rc = compile_pattern(&tok->cased, "\\p{Cased}");
  if (rc == 0) rc = compile_pattern(&tok->case_ignorable, "\\p{Case_Ignorable}");
  if (rc == 0 && !(tok->ctype = newlocale(LC_CTYPE_MASK, "C.UTF-8", (locale_t)0)))
    rc = fg_fail(FG_EIO, "the C.UTF-8 locale is not available for lower-casing");
  if (rc < 0) {
    fg_tokenizer_free(tok);
    return rc;
  }
  *out = tok;
  return 0;
}

int fg_tokenizer_load(fg_tokenizer **out, const char *path) {
  if (!out) return fg_fail(FG_EINVAL, "fg_tokenizer_load: out is NULL");
  *out = NULL;
  if (!path) return fg_fail(FG_EINVAL, "fg_tokenizer_load: path is NULL");
  char *buf;
  size_t len;
  int rc = fg_read_file(path, MAX_FILE_BYTES, &buf, &len);
  if (rc == FG_ERANGE)
    return fg_fail(FG_EFORMAT, "%s is larger than %u MB: not a CLIP merges file", path,
                   MAX_FILE_BYTES >> 20);
  if (rc < 0) return rc;
  rc = fg_tokenizer_load_buffer(out, buf, len);
  free(buf);
  if (rc < 0 && rc != FG_ENOMEM) {
    char detail[512];
    snprintf(detail, sizeof detail, "%s", fg_error_detail());
    fg_fail(rc, "%s: %s", path, detail);
  }
  return rc;
}

int fg_tokenizer_vocab_size(const fg_tokenizer *tok) { return tok ? VOCAB_SIZE : 0; }

/* ---- BPE ------------------------------------------------------------------------------ */

/* Ids written so far; past max they are only counted. */
typedef struct id_sink {
  int32_t *ids; /* [max] */
  size_t max, n;
} id_sink;

static void sink_put(id_sink *s, int32_t id) {
  if (s->n < s->max) s->ids[s->n] = id;
  s->n++;
}

/* Rank of merging symbols a and b, NO_RANK when no merge joins them. */
static int32_t pair_rank(const fg_tokenizer *tok, int32_t a, int32_t b) {
  const pair_slot *p = pair_slot_of(tok->pairs, (uint32_t)a << 16 | (uint32_t)b);
  return p->key == PAIR_EMPTY ? NO_RANK : p->rank;
}

/* BPE of one piece p[0, len) (len >= 1) into out. sym and rank are scratch of len each. */
static void bpe_piece(const fg_tokenizer *tok, const uint8_t *p, size_t len, int32_t *sym,
                      int32_t *rank, id_sink *out) {
  size_t n = len;
  for (size_t i = 0; i + 1 < n; i++) sym[i] = tok->byte_id[p[i]];
  sym[n - 1] = tok->byte_eow_id[p[n - 1]];
  for (size_t i = 0; i + 1 < n; i++) rank[i] = pair_rank(tok, sym[i], sym[i + 1]); /* (n-1) */
  while (n > 1) {
    size_t best = 0;
    int32_t r = NO_RANK;
    for (size_t i = 0; i + 1 < n; i++)
      if (rank[i] < r) r = rank[i], best = i;
    if (r == NO_RANK) break;
    /* best is the first occurrence of the pair: every occurrence has the same rank. */
    int32_t a = sym[best], b = sym[best + 1];
    int32_t m = pair_slot_of(tok->pairs, (uint32_t)a << 16 | (uint32_t)b)->merged;
    size_t w = best;
    for (size_t i = best; i < n;) {
      if (i + 1 < n && sym[i] == a && sym[i + 1] == b) {
        sym[w++] = m;
        i += 2;
      } else {
        sym[w++] = sym[i++];
      }
    }
    n = w;
    for (size_t i = best ? best - 1 : 0; i + 1 < n; i++)
      rank[i] = pair_rank(tok, sym[i], sym[i + 1]);
  }
  for (size_t i = 0; i < n; i++) sink_put(out, sym[i]);
}

/* Cleans, splits and BPE-encodes text into out (SimpleTokenizer.encode). */
static int tokenize(const fg_tokenizer *tok, const char *text, id_sink *out) {
  size_t len = strlen(text);
  if (len > SIZE_MAX / 64) return fg_fail(FG_ENOMEM, "the text is too long to tokenize");
  /* cps [len], low [2 len], utf [8 len]: every stage bounded by its input. */
  uint32_t *cps = malloc((3 * len + 2) * sizeof *cps), *low = cps ? cps + len + 1 : NULL;
  uint8_t *utf = malloc(8 * len + 1);
  int32_t *sym = NULL;
  pcre2_match_data *md = pcre2_match_data_create_from_pattern(tok->pattern, NULL);
  int rc = 0;
  if (!cps || !utf || !md) {
    rc = fg_fail(FG_ENOMEM, "out of memory tokenizing %zu bytes of text", len);
    goto done;
  }
  size_t n = 0, nl = 0, nu = 0;
  if ((rc = fg_clip_utf8_decode((const uint8_t *)text, len, cps, &n)) < 0) goto done;
  n = fg_clip_html_unescape(cps, n);
  n = fg_clip_html_unescape(cps, n);
  n = fg_clip_clean_whitespace(cps, n);
  if ((rc = lower_text(tok, cps, n, low, &nl)) < 0) goto done;
  for (size_t i = 0; i < nl; i++) nu += fg_clip_utf8_put(utf + nu, low[i]);
  if (nu == 0) goto done;
  if (!(sym = malloc(2 * nu * sizeof *sym))) {
    rc = fg_fail(FG_ENOMEM, "out of memory tokenizing %zu bytes of text", len);
    goto done;
  }
  for (size_t at = 0; at < nu;) {
    int m = pcre2_match(tok->pattern, utf, nu, at, PCRE2_NO_UTF_CHECK, md, NULL);
    if (m == PCRE2_ERROR_NOMATCH) break;
    if (m < 0) {
      PCRE2_UCHAR msg[160];
      pcre2_get_error_message(m, msg, sizeof msg);
      rc = fg_fail(m == PCRE2_ERROR_NOMEMORY ? FG_ENOMEM : FG_EINVAL,
                   "splitting the text failed at byte %zu: %s", at, (const char *)msg);
      goto done;
    }
    const PCRE2_SIZE *ov = pcre2_get_ovector_pointer(md);
    const uint8_t *piece = utf + ov[0];
    size_t plen = ov[1] - ov[0];
    if (plen == strlen(SOT_TEXT) && memcmp(piece, SOT_TEXT, plen) == 0)
      sink_put(out, FG_TOKEN_SOT);
    else if (plen == strlen(EOT_TEXT) && memcmp(piece, EOT_TEXT, plen) == 0)
      sink_put(out, FG_TOKEN_EOT);
    else if (plen > 0)
      bpe_piece(tok, piece, plen, sym, sym + nu, out);
    at = ov[1] > at ? ov[1] : at + 1; /* no branch matches empty; never loop on one */
  }
done:
  pcre2_match_data_free(md);
  free(sym);
  free(utf);
  free(cps);
  return rc;
}

/* ---- public entry points -------------------------------------------------------------- */

int fg_tokenizer_bpe(const fg_tokenizer *tok, const char *text, int32_t *ids, size_t max,
                     size_t *n) {
  if (n) *n = 0;
  if (!tok || !text || !n || (!ids && max))
    return fg_fail(FG_EINVAL, "fg_tokenizer_bpe: tok, text, n and ids (when max > 0) are "
                              "required");
  id_sink out = {ids, max, 0};
  FG_TRY(tokenize(tok, text, &out));
  *n = out.n;
  return 0;
}

int fg_tokenizer_encode(const fg_tokenizer *tok, const char *text, int context, int truncate,
                        int32_t *ids, int *n_tokens) {
  if (n_tokens) *n_tokens = 0;
  if (!tok || !text || !ids || context < 2)
    return fg_fail(FG_EINVAL, "fg_tokenizer_encode: tok, text and ids are required and the "
                              "context must be at least 2, got %d", context);
  size_t limit = (size_t)context - 2, n;
  memset(ids, 0, (size_t)context * sizeof *ids);
  int rc = fg_tokenizer_bpe(tok, text, ids + 1, limit, &n);
  if (rc < 0) {
    memset(ids, 0, (size_t)context * sizeof *ids);
    return rc;
  }
  if (n > limit) {
    if (!truncate) {
      memset(ids, 0, (size_t)context * sizeof *ids);
      return fg_fail(FG_ERANGE, "the text is %zu tokens, the limit is %zu", n, limit);
    }
    n = limit; /* clip.tokenize(truncate=True): cut, then the last id becomes the end */
  }
  ids[0] = FG_TOKEN_SOT;
  ids[n + 1] = FG_TOKEN_EOT;
  if (n_tokens) *n_tokens = (int)n + 2;
  return 0;
}

char *fg_tokenizer_decode(const fg_tokenizer *tok, const int32_t *ids, size_t n) {
  if (!tok || (!ids && n)) return NULL;
  size_t raw_len = 0;
  for (size_t i = 0; i < n; i++) {
    if (ids[i] < 0 || ids[i] >= VOCAB_SIZE) {
      fg_fail(FG_EINVAL, "token id %ld at %zu is outside the vocabulary (0 .. %d)",
              (long)ids[i], i, VOCAB_SIZE - 1);
      return NULL;
    }
    if (ids[i] < FG_TOKEN_SOT) raw_len += tok->text_off[ids[i] + 1] - tok->text_off[ids[i]];
  }
  /* raw: the bytes the symbols stand for; out: raw repaired (at most 3 bytes per byte). */
  uint8_t *raw = malloc(raw_len + 1), *out = malloc(3 * raw_len + 1);
  if (!raw || !out) {
    free(raw);
    free(out);
    return NULL;
  }
  size_t r = 0;
  for (size_t i = 0; i < n; i++) {
    if (ids[i] >= FG_TOKEN_SOT) continue; /* start and end tokens are dropped */
    const uint8_t *s = (const uint8_t *)tok->text + tok->text_off[ids[i]];
    const uint8_t *e = (const uint8_t *)tok->text + tok->text_off[ids[i] + 1];
    while (s < e) { /* symbol texts are code points below 324: one or two bytes each */
      uint32_t c = *s;
      if (c >= 0x80) c = (c & 0x1F) << 6 | (*++s & 0x3Fu);
      raw[r++] = tok->unicode_byte[c];
      s++;
    }
  }
  size_t w = fg_clip_utf8_repair(raw, r, out), k = 0;
  for (size_t i = 0; i < w;) { /* "</w>" ends a word: a space */
    if (i + 4 <= w && memcmp(out + i, EOW, 4) == 0) {
      out[k++] = ' ';
      i += 4;
    } else {
      out[k++] = out[i++];
    }
  }
  out[k] = '\0';
  free(raw);
  return (char *)out;
}
