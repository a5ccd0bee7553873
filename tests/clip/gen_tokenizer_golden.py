#!/usr/bin/python3
"""Writes tests/clip/data/tokenizer_golden.tsv, the reference ids for test_tokenizer.c.

A port of OpenAI CLIP's clip/simple_tokenizer.py (SimpleTokenizer) and clip.tokenize, run on
the real merges file, with one deliberate difference: ftfy.fix_text is left out (ftfy is not
packaged for Debian, and the C tokenizer leaves it out as well). Everything else is as the
reference does it: html.unescape twice, strip, runs of regex \\s to one space, str.lower, the
split pattern with the `regex` module and re.IGNORECASE, byte-level BPE.

Run once, by hand, when the inputs change; the output is committed and no test needs Python:
    /usr/bin/python3 tests/clip/gen_tokenizer_golden.py [MERGES_GZ] [OUT_TSV]

One record per line, tab-separated:
    text  bpe_ids  tokenize77  fits  decoded  round_trip
text and decoded escape backslash, tab, newline, carriage return and other control
characters (\\\\ \\t \\n \\r \\xHH); ids are space-separated ("-" for none). bpe_ids is
SimpleTokenizer.encode(text); tokenize77 is clip.tokenize(text, 77, truncate=True) without
the zero padding; fits is 1 when clip.tokenize(text, 77) (truncate=False) does not raise;
decoded is the decode of bpe_ids with the start and end tokens dropped (what
fg_tokenizer_decode returns); round_trip is 1 when encoding decoded gives bpe_ids again.
"""
import gzip
import html
import os
import sys

import regex

HERE = os.path.dirname(os.path.abspath(__file__))
SOT, EOT = "<|startoftext|>", "<|endoftext|>"
CONTEXT = 77


def byte_alphabet():
    """bytes_to_unicode: byte -> the one-character string standing for it."""
    keep = (list(range(ord("!"), ord("~") + 1)) + list(range(ord("¡"), ord("¬") + 1)) +
            list(range(ord("®"), ord("ÿ") + 1)))
    order, chars, extra = list(keep), list(keep), 0
    for b in range(256):
        if b not in keep:
            order.append(b)
            chars.append(256 + extra)
            extra += 1
    return {b: chr(c) for b, c in zip(order, chars)}


class Tokenizer:
    PATTERN = (r"""<\|startoftext\|>|<\|endoftext\|>|'s|'t|'re|'ve|'m|'ll|'d|[\p{L}]+|"""
               r"""[\p{N}]|[^\s\p{L}\p{N}]+""")

    def __init__(self, merges_path):
        self.byte_char = byte_alphabet()
        self.char_byte = {c: b for b, c in self.byte_char.items()}
        lines = gzip.open(merges_path).read().decode("utf-8").split("\n")
        merges = [tuple(line.split()) for line in lines[1:49152 - 256 - 2 + 1]]
        vocab = list(self.byte_char.values())
        vocab += [v + "</w>" for v in vocab]
        vocab += ["".join(m) for m in merges]
        vocab += [SOT, EOT]
        self.encoder = {v: i for i, v in enumerate(vocab)}
        self.decoder = {i: v for v, i in self.encoder.items()}
        self.ranks = {m: i for i, m in enumerate(merges)}
        self.pattern = regex.compile(self.PATTERN, regex.IGNORECASE)

    def bpe(self, piece):
        if piece in (SOT, EOT):
            return [piece]
        word = list(piece[:-1]) + [piece[-1] + "</w>"]
        while len(word) > 1:
            pairs = set(zip(word, word[1:]))
            best = min(pairs, key=lambda p: self.ranks.get(p, float("inf")))
            if best not in self.ranks:
                break
            # every occurrence of the best pair, left to right, in one pass
            merged, i = [], 0
            while i < len(word):
                if i + 1 < len(word) and (word[i], word[i + 1]) == best:
                    merged.append(word[i] + word[i + 1])
                    i += 2
                else:
                    merged.append(word[i])
                    i += 1
            word = merged
        return word

    @staticmethod
    def clean(text):
        text = html.unescape(html.unescape(text)).strip()  # ftfy.fix_text left out
        text = regex.sub(r"\s+", " ", text).strip()
        return text.lower()

    def encode(self, text):
        ids = []
        for piece in self.pattern.findall(self.clean(text)):
            chars = "".join(self.byte_char[b] for b in piece.encode("utf-8"))
            ids += [self.encoder[s] for s in self.bpe(chars)]
        return ids

    def decode(self, ids):
        text = "".join(self.decoder[i] for i in ids if i not in (self.encoder[SOT],
                                                                 self.encoder[EOT]))
        raw = bytearray(self.char_byte[c] for c in text)
        return raw.decode("utf-8", errors="replace").replace("</w>", " ")

    def tokenize(self, text, context=CONTEXT, truncate=False):
        """clip.tokenize for one text, without the zero padding; None where it raises."""
        tokens = [self.encoder[SOT]] + self.encode(text) + [self.encoder[EOT]]
        if len(tokens) > context:
            if not truncate:
                return None
            tokens = tokens[:context]
            tokens[-1] = self.encoder[EOT]
        return tokens


def inputs():
    """The golden inputs: (comment, text)."""
    out = [
        ("known ids", "a photo of a fox"),
        ("known ids", "a dog"),
        ("capitals", "A Photo Of A FOX"),
        ("plain", "a red mug on the table"),
        ("plain", "the quick brown fox jumps over the lazy dog"),
        ("plain", "grasp the handle of the blue screwdriver"),
        ("plain", "caterpillar"),
        ("punctuation", "Hello, World!"),
        ("mixed case", "UPPER lower MiXeD"),
        ("accents", "café"),
        ("accents", "naïve"),
        ("accents", "Zürich"),
        ("accents", "São Paulo"),
        ("accents", "ÀÉÎÕÜ crème brûlée"),
        ("sharp s", "Straße"),
        ("sharp s", "STRASSE und Fuß"),
        ("Greek", "Ελληνικά γράμματα"),
        ("Greek final sigma", "ΟΔΟΣ ΣΑΣ Σ"),
        ("Greek final sigma", "ΣΑΣ. aΣb Σa"),
        ("Cyrillic", "Привет, мир"),
        ("Cyrillic", "МОСКВА"),
        ("CJK", "東京タワー"),
        ("CJK", "中文测试"),
        ("Hangul", "한국어"),
        ("Arabic", "مرحبا بالعالم"),
        ("Hebrew", "שלום"),
        ("digits", "2023"),
        ("digits", "3.14159"),
        ("digits", "version 1.2.3-beta"),
        ("digits", "$100.00 for 50% off"),
        ("digits", "Ⅻ ① ² ٣٤٥"),
        ("symbols", "10×20 ÷ 5 ≈ 3.9°C"),
        ("punctuation runs", "!!!"),
        ("punctuation runs", "..."),
        ("punctuation runs", "?!"),
        ("punctuation runs", "wait... what?!"),
        ("punctuation", "C++ and C# (notes)"),
        ("punctuation", "email@example.com http://x.y/z?q=1&r=2"),
        ("apostrophes", "it's"),
        ("apostrophes", "we'll"),
        ("apostrophes", "don't"),
        ("apostrophes", "O'Neil"),
        ("apostrophes", "'quoted'"),
        ("apostrophes", "I'M HE'D THEY'VE WE'RE"),
        ("apostrophes", "rock 'n' roll"),
        ("entities", "&amp;"),
        ("entities", "&#39;"),
        ("entities", "&lt;b&gt;bold&lt;/b&gt;"),
        ("entities", "&amp;amp; double"),
        ("entities", "&#65;&#x42;&#X43;"),
        ("entities", "a&#x27;s"),
        ("entities, invalid code points", "&#128; &#x99; &#0; &#xD800; &#1114112; &#x1; &#13;x"),
        ("entities", "&quot;hi&quot; &apos;x&apos; a&nbsp;b"),
        ("entities, prefixes", "&ampx &notit; &copy2023 &hellip &hellip; &unknown; &#; &#x;"),
        ("entities", "&#x1F98A; &eacute;t&eacute;"),
        ("entities", "&lt;|endoftext|&gt;"),
        ("emoji", "🦊"),
        ("emoji", "😀😃😄"),
        ("emoji ZWJ", "👨\u200d👩\u200d👧"),
        ("emoji flags", "🇺🇸🇯🇵"),
        ("emoji skin tone", "👍🏽"),
        ("whitespace", "a\tb\nc   d"),
        ("whitespace", "multiple     spaces\t\t\ttabs\n\n\nnewlines"),
        ("whitespace", "\r\n windows \r\n"),
        ("whitespace", "  leading and trailing  "),
        ("whitespace, Unicode", "\u00a0\u2003\u3000x\u2009y\u0085z\u202f"),
        ("whitespace, isspace only", "\x1c edge \x1fin\x1dside"),
        ("empty", ""),
        ("only spaces", "     "),
        ("special tokens", "<|startoftext|>a fox<|endoftext|>"),
        ("special tokens", "<|STARTOFTEXT|> upper special"),
        ("special tokens", "x<|endoftext|>y<|endoftext|"),
        ("long word", "antidisestablishmentarianismsupercalifragilisticexpialidocious"[:60]),
        ("long word", "abcdefghijklmnopqrstuvwxyz" * 3),
        ("long word", "word" * 20),
        ("long input", "a photo of " * 30),
        ("long input, 75 tokens: fits", "a " * 75),
        ("long input, 76 tokens: too long", "a " * 76),
        ("repeated pairs (merged left to right in one pass)", "aaaaaaa zzzzzzzzz mmmmmmmm"),
        ("repeated pairs", "hahahahahaha bananana lololol"),
        ("repeated pairs", "!!!!!!!!!!!! ........ ------"),
        ("mixed scripts", "Tokyo 東京 Москва café 123"),
        ("dotted capital I", "İstanbul"),
        ("title case", "ǅemal"),
        ("Kelvin sign", "\u212a"),
        ("ligature", "ﬁne ﬂow"),
        ("fullwidth", "ｆｕｌｌｗｉｄｔｈ"),
        ("mathematical letters", "𝔘𝔫𝔦𝔠𝔬𝔡𝔢"),
        ("NFD accent (ftfy would compose it)", "cafe\u0301"),
        ("IGNORECASE: 'ſ is a contraction", "it'ſ fine"),
        ("IGNORECASE: U+0345 separates", "a\u0345b"),
        ("U+180E is no White_Space", "x\u180ey"),
        ("control characters", "a\x01b\x7fc"),
        ("replacement character", "\ufffd?"),
    ]
    return out


def escape(s):
    out = []
    for ch in s:
        if ch == "\\":
            out.append("\\\\")
        elif ch == "\t":
            out.append("\\t")
        elif ch == "\n":
            out.append("\\n")
        elif ch == "\r":
            out.append("\\r")
        elif ord(ch) < 0x20 or ord(ch) == 0x7F:
            out.append("\\x%02x" % ord(ch))
        else:
            out.append(ch)
    return "".join(out)


def ids_str(ids):
    return " ".join(str(i) for i in ids) if ids else "-"


def main():
    merges = sys.argv[1] if len(sys.argv) > 1 else os.path.join(
        HERE, "..", "..", "..", "shared", "data", "clip", "bpe_simple_vocab_16e6.txt.gz")
    out_path = sys.argv[2] if len(sys.argv) > 2 else os.path.join(HERE, "data",
                                                                   "tokenizer_golden.tsv")
    tok = Tokenizer(merges)
    assert tok.tokenize("a photo of a fox") == [49406, 320, 1125, 539, 320, 3240, 49407]
    assert tok.tokenize("a dog") == [49406, 320, 1929, 49407]
    rows = []
    for _, text in inputs():
        ids = tok.encode(text)
        tok77 = tok.tokenize(text, truncate=True)
        fits = tok.tokenize(text) is not None
        decoded = tok.decode(ids)
        round_trip = tok.encode(decoded) == ids
        rows.append("\t".join([escape(text), ids_str(ids), ids_str(tok77), str(int(fits)),
                               escape(decoded), str(int(round_trip))]))
    os.makedirs(os.path.dirname(out_path), exist_ok=True)
    with open(out_path, "w", encoding="utf-8", newline="\n") as f:
        f.write("\n".join(rows) + "\n")
    print("%d records -> %s" % (len(rows), out_path))


if __name__ == "__main__":
    main()
