//! The mutator: byte-level edits for any input and structure-aware edits for RON and mesh text
//! (numbers replaced by edge values, bracketed groups deleted, duplicated or swapped, tokens
//! spliced in from other corpus entries). Deterministic: the same seed gives the same inputs.

use modesuite_engine::rng::EnvRng;

/// Numbers that reach the edges of parsers and validators: zero, signs, subnormals, overflow
/// in f32 and integer types, non-finite values, huge counts.
const EDGE_NUMBERS: &[&str] = &[
    "0",
    "-0.0",
    "1",
    "-1",
    "0.5",
    "2",
    "1e-320",
    "1e-9",
    "3.5e38",
    "1e308",
    "-1e308",
    "1e400",
    "NaN",
    "inf",
    "-inf",
    "255",
    "65536",
    "2147483648",
    "4294967296",
    "-2147483649",
    "9223372036854775808",
    "18446744073709551616",
    "1000000000",
];

/// Short texts that are often meaningful in the inputs (RON syntax, mesh keywords).
const TOKENS: &[&str] = &[
    "(",
    ")",
    "[",
    "]",
    "{",
    "}",
    ",",
    ":",
    "\"",
    "Some(",
    "None",
    "true",
    "false",
    "()",
    "\n",
    "$EndNodes",
    "$Elements",
    "$EndElements",
    "$Nodes",
    "Vertices",
    "Tetrahedra",
    "End",
    "f ",
    "v ",
    "facet normal",
    "endloop",
    "solid",
    "//",
    "/*",
    "r#\"",
    "\\u{0}",
];

/// A deterministic input mutator.
pub struct Mutator {
    rng: EnvRng,
}

impl Mutator {
    /// A mutator whose choices come from `seed`.
    pub fn new(seed: u64) -> Self {
        Self {
            rng: EnvRng::from_seed(seed),
        }
    }

    /// A number in `0..n` (`n > 0`).
    pub fn below(&mut self, n: usize) -> usize {
        (self.rng.next_u64() % n.max(1) as u64) as usize
    }

    /// A new input made from `input` by one to four edits; `corpus` gives splicing material.
    pub fn mutate(&mut self, input: &[u8], corpus: &[Vec<u8>]) -> Vec<u8> {
        let mut out = input.to_vec();
        let edits = 1 + self.below(4);
        for _ in 0..edits {
            let text_like = out.iter().take(512).all(|b| b.is_ascii() && *b != 0);
            let op = self.below(if text_like { 14 } else { 7 });
            match op {
                0 => self.flip_bit(&mut out),
                1 => self.set_byte(&mut out),
                2 => self.delete_range(&mut out),
                3 => self.duplicate_range(&mut out),
                4 => self.truncate(&mut out),
                5 => self.splice(&mut out, corpus),
                6 => self.overwrite_u32(&mut out),
                7..=9 => self.replace_number(&mut out),
                10 => self.insert_token(&mut out),
                11 => self.delete_group(&mut out),
                12 => self.duplicate_group(&mut out),
                _ => self.swap_words(&mut out),
            }
        }
        out
    }

    fn flip_bit(&mut self, b: &mut [u8]) {
        if !b.is_empty() {
            let i = self.below(b.len());
            b[i] ^= 1 << self.below(8);
        }
    }

    fn set_byte(&mut self, b: &mut [u8]) {
        if !b.is_empty() {
            let i = self.below(b.len());
            b[i] = [0u8, 0xff, b'0', b'9', b'-', b'.', b'e', b' ', b'\n'][self.below(9)];
        }
    }

    fn range(&mut self, len: usize) -> (usize, usize) {
        let a = self.below(len + 1);
        let n = 1 + self.below(16.min(len - a.min(len)) + 1);
        (a, (a + n).min(len))
    }

    fn delete_range(&mut self, b: &mut Vec<u8>) {
        let (a, e) = self.range(b.len());
        b.drain(a..e);
    }

    fn duplicate_range(&mut self, b: &mut Vec<u8>) {
        let (a, e) = self.range(b.len());
        let piece = b[a..e].to_vec();
        let at = self.below(b.len() + 1);
        b.splice(at..at, piece);
    }

    fn truncate(&mut self, b: &mut Vec<u8>) {
        let at = self.below(b.len() + 1);
        b.truncate(at);
    }

    fn splice(&mut self, b: &mut Vec<u8>, corpus: &[Vec<u8>]) {
        if corpus.is_empty() {
            return;
        }
        let other = &corpus[self.below(corpus.len())];
        let (a, e) = self.range(other.len());
        let at = self.below(b.len() + 1);
        b.splice(at..at, other[a..e].iter().copied());
    }

    fn overwrite_u32(&mut self, b: &mut [u8]) {
        if b.len() >= 4 {
            let i = self.below(b.len() - 3);
            let v: u32 = [0, 1, u32::MAX, 0x7fff_ffff, 0x8000_0000, 1 << 20][self.below(6)];
            b[i..i + 4].copy_from_slice(&v.to_le_bytes());
        }
    }

    /// Spans of numbers (digits with signs, dots and exponents) in the text.
    fn numbers(b: &[u8]) -> Vec<(usize, usize)> {
        let mut out = Vec::new();
        let mut i = 0;
        while i < b.len() {
            let starts = b[i].is_ascii_digit()
                && (i == 0 || !(b[i - 1].is_ascii_alphanumeric() || b[i - 1] == b'_'));
            if starts {
                let s = if i > 0 && b[i - 1] == b'-' { i - 1 } else { i };
                let mut e = i;
                while e < b.len()
                    && (b[e].is_ascii_digit()
                        || b[e] == b'.'
                        || b[e] == b'e'
                        || b[e] == b'E'
                        || (matches!(b[e], b'-' | b'+') && matches!(b[e - 1], b'e' | b'E')))
                {
                    e += 1;
                }
                out.push((s, e));
                i = e;
            } else {
                i += 1;
            }
        }
        out
    }

    fn replace_number(&mut self, b: &mut Vec<u8>) {
        let spans = Self::numbers(b);
        if spans.is_empty() {
            return self.insert_token(b);
        }
        let (s, e) = spans[self.below(spans.len())];
        let new = EDGE_NUMBERS[self.below(EDGE_NUMBERS.len())].as_bytes();
        b.splice(s..e, new.iter().copied());
    }

    fn insert_token(&mut self, b: &mut Vec<u8>) {
        let at = self.below(b.len() + 1);
        let t = TOKENS[self.below(TOKENS.len())].as_bytes();
        b.splice(at..at, t.iter().copied());
    }

    /// A balanced bracketed group starting at a random opening bracket.
    fn group(&mut self, b: &[u8]) -> Option<(usize, usize)> {
        let opens: Vec<usize> = (0..b.len())
            .filter(|&i| matches!(b[i], b'(' | b'[' | b'{'))
            .collect();
        if opens.is_empty() {
            return None;
        }
        let s = opens[self.below(opens.len())];
        let mut depth = 0i32;
        for (k, c) in b[s..].iter().enumerate() {
            match c {
                b'(' | b'[' | b'{' => depth += 1,
                b')' | b']' | b'}' => {
                    depth -= 1;
                    if depth == 0 {
                        return Some((s, s + k + 1));
                    }
                }
                _ => {}
            }
        }
        None
    }

    fn delete_group(&mut self, b: &mut Vec<u8>) {
        if let Some((s, e)) = self.group(b) {
            b.drain(s..e);
        }
    }

    fn duplicate_group(&mut self, b: &mut Vec<u8>) {
        if let Some((s, e)) = self.group(b) {
            let piece: Vec<u8> = b[s..e].to_vec();
            let mut with_comma = vec![b','];
            with_comma.extend(piece);
            b.splice(e..e, with_comma);
        }
    }

    /// Swaps two identifier-or-string words of the text (a field name into another's place).
    fn swap_words(&mut self, b: &mut Vec<u8>) {
        let mut words = Vec::new();
        let mut i = 0;
        while i < b.len() {
            if b[i].is_ascii_alphabetic() || b[i] == b'_' {
                let s = i;
                while i < b.len() && (b[i].is_ascii_alphanumeric() || b[i] == b'_' || b[i] == b'.')
                {
                    i += 1;
                }
                words.push((s, i));
            } else {
                i += 1;
            }
        }
        if words.len() < 2 {
            return;
        }
        let (s1, e1) = words[self.below(words.len())];
        let replacement = {
            let (s2, e2) = words[self.below(words.len())];
            b[s2..e2].to_vec()
        };
        b.splice(s1..e1, replacement);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn same_seed_same_inputs_and_numbers_found() {
        let text = b"(a: 1.5e-3, b: -2, c: [3, 4])".to_vec();
        assert_eq!(
            Mutator::numbers(&text)
                .iter()
                .map(|&(s, e)| std::str::from_utf8(&text[s..e]).unwrap())
                .collect::<Vec<_>>(),
            ["1.5e-3", "-2", "3", "4"]
        );
        let run = |seed| {
            let mut m = Mutator::new(seed);
            (0..50)
                .map(|_| m.mutate(&text, std::slice::from_ref(&text)))
                .collect::<Vec<_>>()
        };
        assert_eq!(run(7), run(7));
        assert_ne!(run(7), run(8));
    }
}
