/* CLIP's text cleaning on code points (text_clean.h): UTF-8, html.unescape, whitespace. */
#include "clip/text_clean.h"
#include "core/error.h"

#include <stdint.h>
#include <string.h>

/* ---- UTF-8 ---------------------------------------------------------------------------- */

/* Writes c (<= U+10FFFF, not a surrogate) as UTF-8; returns the byte count (1-4). */
size_t fg_clip_utf8_put(uint8_t *o, uint32_t c) {
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
int fg_clip_utf8_decode(const uint8_t *s, size_t len, uint32_t *out, size_t *n) {
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
size_t fg_clip_utf8_repair(const uint8_t *s, size_t len, uint8_t *out) {
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
      w += fg_clip_utf8_put(out + w, 0xFFFD);
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
size_t fg_clip_html_unescape(uint32_t *c, size_t n) {
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
int fg_clip_is_white_space(uint32_t c) {
  return (c >= 0x09 && c <= 0x0D) || c == 0x20 || c == 0x85 || c == 0xA0 || c == 0x1680 ||
         (c >= 0x2000 && c <= 0x200A) || c == 0x2028 || c == 0x2029 || c == 0x202F ||
         c == 0x205F || c == 0x3000;
}

/* Python's str.isspace, which strip() uses: White_Space plus the separators U+001C-U+001F. */
int fg_clip_is_py_space(uint32_t c) {
  return fg_clip_is_white_space(c) || (c >= 0x1C && c <= 0x1F);
}

/* strip(), then every run of White_Space to one space, in place; returns the new length. A
 * stripped text begins and ends with a character that is no White_Space, so the
 * reference's second strip() would remove nothing. */
size_t fg_clip_clean_whitespace(uint32_t *c, size_t n) {
  size_t b = 0, e = n, w = 0;
  while (b < e && fg_clip_is_py_space(c[b])) b++;
  while (e > b && fg_clip_is_py_space(c[e - 1])) e--;
  for (size_t i = b; i < e;) {
    if (fg_clip_is_white_space(c[i])) {
      while (fg_clip_is_white_space(c[i])) i++; /* stops before e: c[e - 1] is no space */
      c[w++] = ' ';
    } else {
      c[w++] = c[i++];
    }
  }
  return w;
}
