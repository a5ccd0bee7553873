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

/* ---- UTF-8 ---------------------------------------------------------------------------- */

/* Writes c (<= U+10FFFF, not a surrogate) as UTF-8; returns the byte count (1-4). */
static size_t utf8_put(uint8_t *o, uint32_t c) {
  if (c < 0x80) {
    o[0] = (uint8_t)c;
    return 1;
  }
  if (c < 0x800) {
    o[0] = (uint8_t)(0xC0 | c >> 6);
    o[1] = (uint8_t)(0x80 | (c & 0x3F));
    return 2;
  }
  if (c < 0x10000) {
    o[0] = (uint8_t)(0xE0 | c >> 12);
    o[1] = (uint8_t)(0x80 | (c >> 6 & 0x3F));
    o[2] = (uint8_t)(0x80 | (c & 0x3F));
    return 3;
  }
  o[0] = (uint8_t)(0xF0 | c >> 18);
  o[1] = (uint8_t)(0x80 | (c >> 12 & 0x3F));
  o[2] = (uint8_t)(0x80 | (c >> 6 & 0x3F));
  o[3] = (uint8_t)(0x80 | (c & 0x3F));
  return 4;
}

/* The range the second byte of a sequence led by b must lie in (RFC 3629, table 3-7 of the
 * Unicode standard), which excludes overlong forms, surrogates and code points past
 * U+10FFFF; later continuation bytes are 80..BF. Returns the sequence length, 0 for a byte
 * that cannot lead one. */
static int utf8_lead(uint8_t b, uint8_t *lo, uint8_t *hi) {
  *lo = 0x80;
  *hi = 0xBF;
  if (b >= 0xC2 && b <= 0xDF) return 2;
  if (b >= 0xE0 && b <= 0xEF) {
    if (b == 0xE0) *lo = 0xA0;
    if (b == 0xED) *hi = 0x9F;
    return 3;
  }
  if (b >= 0xF0 && b <= 0xF4) {
    if (b == 0xF0) *lo = 0x90;
    if (b == 0xF4) *hi = 0x8F;
    return 4;
  }
  return 0;
}

/* Decodes strict UTF-8 s[0, len) into out (room for len code points); *n receives the count.
 * FG_EINVAL names the byte offset of the first bad sequence and what is wrong with it. */
static int utf8_decode(const uint8_t *s, size_t len, uint32_t *out, size_t *n) {
  size_t w = 0;
  for (size_t i = 0; i < len;) {
    uint8_t b = s[i], lo, hi;
    if (b < 0x80) {
      out[w++] = b;
      i++;
      continue;
    }
    int need = utf8_lead(b, &lo, &hi);
    const char *why = NULL;
    if (need == 0) {
      why = b <= 0xBF                ? "a continuation byte without a lead byte"
            : b == 0xC0 || b == 0xC1 ? "an overlong encoding"
                                     : "a byte that never occurs in UTF-8";
    } else if (i + 1 >= len || s[i + 1] < 0x80 || s[i + 1] > 0xBF) {
      why = "a sequence cut short";
    } else if (s[i + 1] < lo) {
      why = "an overlong encoding";
    } else if (s[i + 1] > hi) {
      why = b == 0xED ? "an encoded surrogate" : "a code point beyond U+10FFFF";
    }
    uint32_t c = b & (0x7Fu >> need);
    for (int k = 1; !why && k < need; k++) {
      if (i + (size_t)k >= len || (s[i + k] & 0xC0) != 0x80)
        why = "a sequence cut short";
      else
        c = c << 6 | (s[i + k] & 0x3Fu);
    }
    if (why)
      return fg_fail(FG_EINVAL, "the text is not valid UTF-8 at byte %zu (0x%02x): %s", i, b,
                     why);
    out[w++] = c;
    i += (size_t)need;
  }
  *n = w;
  return 0;
}

/* Copies s[0, len) to out replacing each maximal ill-formed subsequence with U+FFFD, as
 * Python's bytes.decode("utf-8", errors="replace"); out needs room for 3 * len bytes.
 * Returns the bytes written. */
static size_t utf8_repair(const uint8_t *s, size_t len, uint8_t *out) {
  size_t w = 0;
  for (size_t i = 0; i < len;) {
    uint8_t lo, hi;
    int need = s[i] < 0x80 ? 1 : utf8_lead(s[i], &lo, &hi);
    int got = need ? 1 : 0;
    while (got > 0 && got < need && i + (size_t)got < len) {
      uint8_t c = s[i + got];
      if (got == 1 ? (c < lo || c > hi) : (c & 0xC0) != 0x80) break;
      got++;
    }
    if (need && got == need) {
      memcpy(out + w, s + i, (size_t)need);
      w += (size_t)need;
      i += (size_t)need;
    } else {
      w += utf8_put(out + w, 0xFFFD);
      i += got ? (size_t)got : 1;
    }
  }
  return w;
}

/* ---- html.unescape -------------------------------------------------------------------- */

typedef struct entity {
  const char *name; /* without the semicolon */
  uint32_t cp;
  uint8_t bare; /* also recognised without a semicolon (HTML 5's legacy names) */
} entity;

/* Sorted by strcmp of the names, for the binary search. */
static const entity entities[] = {
    {"AElig", 0xC6, 1}, {"AMP", 0x26, 1}, {"Aacute", 0xC1, 1}, {"Acirc", 0xC2, 1},
    {"Agrave", 0xC0, 1}, {"Alpha", 0x391, 0}, {"Aring", 0xC5, 1}, {"Atilde", 0xC3, 1},
    {"Auml", 0xC4, 1}, {"Beta", 0x392, 0}, {"COPY", 0xA9, 1}, {"Ccedil", 0xC7, 1},
    {"Chi", 0x3A7, 0}, {"Dagger", 0x2021, 0}, {"Delta", 0x394, 0}, {"ETH", 0xD0, 1},
    {"Eacute", 0xC9, 1}, {"Ecirc", 0xCA, 1}, {"Egrave", 0xC8, 1}, {"Epsilon", 0x395, 0},
    {"Eta", 0x397, 0}, {"Euml", 0xCB, 1}, {"GT", 0x3E, 1}, {"Gamma", 0x393, 0}, {"Iacute", 0xCD, 1},
    {"Icirc", 0xCE, 1}, {"Igrave", 0xCC, 1}, {"Iota", 0x399, 0}, {"Iuml", 0xCF, 1},
    {"Kappa", 0x39A, 0}, {"LT", 0x3C, 1}, {"Lambda", 0x39B, 0}, {"Mu", 0x39C, 0},
    {"Ntilde", 0xD1, 1}, {"Nu", 0x39D, 0}, {"OElig", 0x152, 0}, {"Oacute", 0xD3, 1},
    {"Ocirc", 0xD4, 1}, {"Ograve", 0xD2, 1}, {"Omega", 0x3A9, 0}, {"Omicron", 0x39F, 0},
    {"Oslash", 0xD8, 1}, {"Otilde", 0xD5, 1}, {"Ouml", 0xD6, 1}, {"Phi", 0x3A6, 0},
    {"Pi", 0x3A0, 0}, {"Prime", 0x2033, 0}, {"Psi", 0x3A8, 0}, {"QUOT", 0x22, 1}, {"REG", 0xAE, 1},
    {"Rho", 0x3A1, 0}, {"Scaron", 0x160, 0}, {"Sigma", 0x3A3, 0}, {"THORN", 0xDE, 1},
    {"Tau", 0x3A4, 0}, {"Theta", 0x398, 0}, {"Uacute", 0xDA, 1}, {"Ucirc", 0xDB, 1},
    {"Ugrave", 0xD9, 1}, {"Upsilon", 0x3A5, 0}, {"Uuml", 0xDC, 1}, {"Xi", 0x39E, 0},
    {"Yacute", 0xDD, 1}, {"Yuml", 0x178, 0}, {"Zeta", 0x396, 0}, {"aacute", 0xE1, 1},
    {"acirc", 0xE2, 1}, {"acute", 0xB4, 1}, {"aelig", 0xE6, 1}, {"agrave", 0xE0, 1},
    {"alefsym", 0x2135, 0}, {"alpha", 0x3B1, 0}, {"amp", 0x26, 1}, {"and", 0x2227, 0},
    {"ang", 0x2220, 0}, {"apos", 0x27, 0}, {"aring", 0xE5, 1}, {"asymp", 0x2248, 0},
    {"atilde", 0xE3, 1}, {"auml", 0xE4, 1}, {"bdquo", 0x201E, 0}, {"beta", 0x3B2, 0},
    {"brvbar", 0xA6, 1}, {"bull", 0x2022, 0}, {"cap", 0x2229, 0}, {"ccedil", 0xE7, 1},
    {"cedil", 0xB8, 1}, {"cent", 0xA2, 1}, {"chi", 0x3C7, 0}, {"circ", 0x2C6, 0},
    {"clubs", 0x2663, 0}, {"cong", 0x2245, 0}, {"copy", 0xA9, 1}, {"crarr", 0x21B5, 0},
    {"cup", 0x222A, 0}, {"curren", 0xA4, 1}, {"dArr", 0x21D3, 0}, {"dagger", 0x2020, 0},
    {"darr", 0x2193, 0}, {"deg", 0xB0, 1}, {"delta", 0x3B4, 0}, {"diams", 0x2666, 0},
    {"divide", 0xF7, 1}, {"eacute", 0xE9, 1}, {"ecirc", 0xEA, 1}, {"egrave", 0xE8, 1},
    {"empty", 0x2205, 0}, {"emsp", 0x2003, 0}, {"ensp", 0x2002, 0}, {"epsilon", 0x3B5, 0},
    {"equiv", 0x2261, 0}, {"eta", 0x3B7, 0}, {"eth", 0xF0, 1}, {"euml", 0xEB, 1},
    {"euro", 0x20AC, 0}, {"exist", 0x2203, 0}, {"fnof", 0x192, 0}, {"forall", 0x2200, 0},
    {"frac12", 0xBD, 1}, {"frac14", 0xBC, 1}, {"frac34", 0xBE, 1}, {"frasl", 0x2044, 0},
    {"gamma", 0x3B3, 0}, {"ge", 0x2265, 0}, {"gt", 0x3E, 1}, {"hArr", 0x21D4, 0},
    {"harr", 0x2194, 0}, {"hearts", 0x2665, 0}, {"hellip", 0x2026, 0}, {"iacute", 0xED, 1},
    {"icirc", 0xEE, 1}, {"iexcl", 0xA1, 1}, {"igrave", 0xEC, 1}, {"image", 0x2111, 0},
    {"infin", 0x221E, 0}, {"int", 0x222B, 0}, {"iota", 0x3B9, 0}, {"iquest", 0xBF, 1},
    {"isin", 0x2208, 0}, {"iuml", 0xEF, 1}, {"kappa", 0x3BA, 0}, {"lArr", 0x21D0, 0},
    {"lambda", 0x3BB, 0}, {"lang", 0x27E8, 0}, {"laquo", 0xAB, 1}, {"larr", 0x2190, 0},
    {"lceil", 0x2308, 0}, {"ldquo", 0x201C, 0}, {"le", 0x2264, 0}, {"lfloor", 0x230A, 0},
    {"lowast", 0x2217, 0}, {"loz", 0x25CA, 0}, {"lrm", 0x200E, 0}, {"lsaquo", 0x2039, 0},
    {"lsquo", 0x2018, 0}, {"lt", 0x3C, 1}, {"macr", 0xAF, 1}, {"mdash", 0x2014, 0},
    {"micro", 0xB5, 1}, {"middot", 0xB7, 1}, {"minus", 0x2212, 0}, {"mu", 0x3BC, 0},
    {"nabla", 0x2207, 0}, {"nbsp", 0xA0, 1}, {"ndash", 0x2013, 0}, {"ne", 0x2260, 0},
    {"ni", 0x220B, 0}, {"not", 0xAC, 1}, {"notin", 0x2209, 0}, {"nsub", 0x2284, 0},
    {"ntilde", 0xF1, 1}, {"nu", 0x3BD, 0}, {"oacute", 0xF3, 1}, {"ocirc", 0xF4, 1},
    {"oelig", 0x153, 0}, {"ograve", 0xF2, 1}, {"oline", 0x203E, 0}, {"omega", 0x3C9, 0},
    {"omicron", 0x3BF, 0}, {"oplus", 0x2295, 0}, {"or", 0x2228, 0}, {"ordf", 0xAA, 1},
    {"ordm", 0xBA, 1}, {"oslash", 0xF8, 1}, {"otilde", 0xF5, 1}, {"otimes", 0x2297, 0},
    {"ouml", 0xF6, 1}, {"para", 0xB6, 1}, {"part", 0x2202, 0}, {"permil", 0x2030, 0},
    {"perp", 0x22A5, 0}, {"phi", 0x3C6, 0}, {"pi", 0x3C0, 0}, {"piv", 0x3D6, 0},
    {"plusmn", 0xB1, 1}, {"pound", 0xA3, 1}, {"prime", 0x2032, 0}, {"prod", 0x220F, 0},
    {"prop", 0x221D, 0}, {"psi", 0x3C8, 0}, {"quot", 0x22, 1}, {"rArr", 0x21D2, 0},
    {"radic", 0x221A, 0}, {"rang", 0x27E9, 0}, {"raquo", 0xBB, 1}, {"rarr", 0x2192, 0},
    {"rceil", 0x2309, 0}, {"rdquo", 0x201D, 0}, {"real", 0x211C, 0}, {"reg", 0xAE, 1},
    {"rfloor", 0x230B, 0}, {"rho", 0x3C1, 0}, {"rlm", 0x200F, 0}, {"rsaquo", 0x203A, 0},
    {"rsquo", 0x2019, 0}, {"sbquo", 0x201A, 0}, {"scaron", 0x161, 0}, {"sdot", 0x22C5, 0},
    {"sect", 0xA7, 1}, {"shy", 0xAD, 1}, {"sigma", 0x3C3, 0}, {"sigmaf", 0x3C2, 0},
    {"sim", 0x223C, 0}, {"spades", 0x2660, 0}, {"sub", 0x2282, 0}, {"sube", 0x2286, 0},
    {"sum", 0x2211, 0}, {"sup", 0x2283, 0}, {"sup1", 0xB9, 1}, {"sup2", 0xB2, 1}, {"sup3", 0xB3, 1},
    {"supe", 0x2287, 0}, {"szlig", 0xDF, 1}, {"tau", 0x3C4, 0}, {"there4", 0x2234, 0},
    {"theta", 0x3B8, 0}, {"thetasym", 0x3D1, 0}, {"thinsp", 0x2009, 0}, {"thorn", 0xFE, 1},
    {"tilde", 0x2DC, 0}, {"times", 0xD7, 1}, {"trade", 0x2122, 0}, {"uArr", 0x21D1, 0},
    {"uacute", 0xFA, 1}, {"uarr", 0x2191, 0}, {"ucirc", 0xFB, 1}, {"ugrave", 0xF9, 1},
    {"uml", 0xA8, 1}, {"upsih", 0x3D2, 0}, {"upsilon", 0x3C5, 0}, {"uuml", 0xFC, 1},
    {"weierp", 0x2118, 0}, {"xi", 0x3BE, 0}, {"yacute", 0xFD, 1}, {"yen", 0xA5, 1},
    {"yuml", 0xFF, 1}, {"zeta", 0x3B6, 0}, {"zwj", 0x200D, 0}, {"zwnj", 0x200C, 0},
};

/* What a numeric reference to 0x80-0x9f stands for (windows-1252; the five holes stay as they
 * are), as Python's html._invalid_charrefs. */
static const uint16_t cp1252_c1[32] = {
    0x20AC, 0x81,   0x201A, 0x0192, 0x201E, 0x2026, 0x2020, 0x2021, 0x02C6, 0x2030, 0x0160,
    0x2039, 0x0152, 0x8D,   0x017D, 0x8F,   0x90,   0x2018, 0x2019, 0x201C, 0x201D, 0x2022,
    0x2013, 0x2014, 0x02DC, 0x2122, 0x0161, 0x203A, 0x0153, 0x9D,   0x017E, 0x0178};

/* Looks up the name s[0, len); bare_only restricts the search to names valid without a
 * semicolon. NULL when there is none (including names with non-ASCII characters). */
static const entity *entity_find(const uint32_t *s, size_t len, int bare_only) {
  char key[9];
  if (len == 0 || len >= sizeof key) return NULL;
  for (size_t i = 0; i < len; i++) {
    if (s[i] >= 0x80) return NULL;
    key[i] = (char)s[i];
  }
  key[len] = '\0';
  size_t lo = 0, hi = sizeof entities / sizeof entities[0];
  while (lo < hi) {
    size_t mid = lo + (hi - lo) / 2;
    int c = strcmp(entities[mid].name, key);
    if (c == 0) return bare_only && !entities[mid].bare ? NULL : &entities[mid];
    if (c < 0)
      lo = mid + 1;
    else
      hi = mid;
  }
  return NULL;
}

/* The code point a numeric reference stands for, 0 for none (the reference drops it), by
 * Python's html._replace_charref. num is saturated at 0x110000. */
static uint32_t numeric_ref(uint32_t num) {
  if (num == 0) return 0xFFFD;
  if (num >= 0x80 && num <= 0x9F) return cp1252_c1[num - 0x80];
  if ((num >= 0xD800 && num <= 0xDFFF) || num > 0x10FFFF) return 0xFFFD;
  if ((num >= 0x01 && num <= 0x08) || num == 0x0B || (num >= 0x0E && num <= 0x1F) ||
      num == 0x7F || (num >= 0xFDD0 && num <= 0xFDEF) || (num & 0xFFFE) == 0xFFFE)
    return 0;
  return num; /* includes 0x0D, which Python maps to itself */
}

static int is_hex(uint32_t c) {
  return (c >= '0' && c <= '9') || (c >= 'a' && c <= 'f') || (c >= 'A' && c <= 'F');
}

static uint32_t hex_val(uint32_t c) {
  return c <= '9' ? c - '0' : (c | 0x20) - 'a' + 10;
}

/* One pass of Python's html.unescape over c[0, n), in place (no reference is shorter than
 * what replaces it). Python's pattern is
 *   &(#[0-9]+;?|#[xX][0-9a-fA-F]+;?|[^\t\n\f <&#;]{1,32};?)
 * and a named reference that is not a known name is replaced by its longest known prefix
 * among the names valid without a semicolon, the rest kept. Returns the new length. */
static size_t html_unescape(uint32_t *c, size_t n) {
  size_t w = 0;
  for (size_t r = 0; r < n;) {
    if (c[r] != '&') {
      c[w++] = c[r++];
      continue;
    }
    size_t i = r + 1;
    if (i < n && c[i] == '#') {
      int hex = i + 1 < n && (c[i + 1] == 'x' || c[i + 1] == 'X');
      size_t j = i + 1 + (size_t)hex, d0 = j;
      uint32_t num = 0;
      while (j < n && (hex ? is_hex(c[j]) : c[j] >= '0' && c[j] <= '9')) {
        uint32_t d = hex ? hex_val(c[j]) : c[j] - '0';
        num = num > 0x10FFFF ? 0x110000 : num * (hex ? 16 : 10) + d;
        j++;
      }
      if (j == d0) { /* "&#" or "&#x" without digits is not a reference */
        c[w++] = c[r++];
        continue;
      }
      if (num > 0x10FFFF) num = 0x110000;
      if (j < n && c[j] == ';') j++;
      uint32_t v = numeric_ref(num);
      if (v) c[w++] = v;
      r = j;
      continue;
    }
    size_t j = i;
    while (j < n && j - i < 32 && c[j] != '\t' && c[j] != '\n' && c[j] != '\f' && c[j] != ' ' &&
           c[j] != '<' && c[j] != '&' && c[j] != '#' && c[j] != ';')
      j++;
    size_t len = j - i;
    int semi = j < n && c[j] == ';';
    const entity *e = len ? entity_find(c + i, len, !semi) : NULL;
    size_t end = j + (size_t)semi, keep = end; /* keep: where the characters left begin */
    for (size_t x = end - i - 1; !e && len && x >= 2; x--) {
      e = entity_find(c + i, x, 1);
      keep = i + x;
    }
    if (!e) { /* not a reference: the '&' and what follows stay as they are */
      c[w++] = c[r++];
      continue;
    }
    c[w++] = e->cp;
    for (size_t k = keep; k < end; k++) c[w++] = c[k];
    r = end;
  }
  return w;
}

/* ---- whitespace and lower case -------------------------------------------------------- */

/* \s of the regex module on str: the White_Space property. */
static int is_white_space(uint32_t c) {
  return (c >= 0x09 && c <= 0x0D) || c == 0x20 || c == 0x85 || c == 0xA0 || c == 0x1680 ||
         (c >= 0x2000 && c <= 0x200A) || c == 0x2028 || c == 0x2029 || c == 0x202F ||
         c == 0x205F || c == 0x3000;
}

/* Python's str.isspace, which strip() uses: White_Space plus the separators U+001C-U+001F. */
static int is_py_space(uint32_t c) { return is_white_space(c) || (c >= 0x1C && c <= 0x1F); }

/* strip(), then every run of White_Space to one space, in place; returns the new length. A
 * stripped text begins and ends with a character that is no White_Space, so the
 * reference's second strip() would remove nothing. */
static size_t clean_whitespace(uint32_t *c, size_t n) {
  size_t b = 0, e = n, w = 0;
  while (b < e && is_py_space(c[b])) b++;
  while (e > b && is_py_space(c[e - 1])) e--;
  for (size_t i = b; i < e;) {
    if (is_white_space(c[i])) {
      while (is_white_space(c[i])) i++; /* stops before e: c[e - 1] is no space */
      c[w++] = ' ';
    } else {
      c[w++] = c[i++];
    }
  }
  return w;
}

/* Whether c has the property of re (an anchored single-property pattern). */
static int has_property(const pcre2_code *re, pcre2_match_data *md, uint32_t c) {
  uint8_t buf[4];
  size_t len = utf8_put(buf, c);
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
    t += (uint32_t)utf8_put((uint8_t *)tok->text + t, cs[i & 255]);
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
  if ((rc = utf8_decode((const uint8_t *)text, len, cps, &n)) < 0) goto done;
  n = html_unescape(cps, n);
  n = html_unescape(cps, n);
  n = clean_whitespace(cps, n);
  if ((rc = lower_text(tok, cps, n, low, &nl)) < 0) goto done;
  for (size_t i = 0; i < nl; i++) nu += utf8_put(utf + nu, low[i]);
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
  size_t w = utf8_repair(raw, r, out), k = 0;
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
