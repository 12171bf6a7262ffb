//! Numbers as a file printed them: the integer of their printed digits, the power of ten of
//! the last one, and the notation — enough to print the same characters again.
//!
//! Why: a BVH archive should give back the MOTION block the user uploaded value for value,
//! and the printed precision is also what makes lossless coding cheap (a value printed with
//! four decimals is an integer count of 0.0001). A value is kept in one of three notations:
//! - [`Notation::Fixed`]: `-?(0|[1-9][0-9]*)(\.[0-9]+)?`, as `%f` and most exporters print;
//! - [`Notation::ExpC`]: `-?[1-9](\.[0-9]+)?e[+-][0-9]{2,}`, as C's `%e`/`%g` print;
//! - [`Notation::ExpShort`]: `-?[1-9](\.[0-9]+)?e-?[1-9][0-9]*|e0`, as Rust and JavaScript print;
//!
//! and a token in none of them (a leading `+`, `.5`, `1E5`, more than 18 digits) is kept
//! verbatim. [`Printed::read`] accepts a token only if printing it back gives the same
//! characters, so the three notations round-trip by construction.

use std::fmt::Write as _;

/// Digits beyond this many do not fit the integer (i64) exactly; such tokens are verbatim.
const MAX_DIGITS: usize = 18;

/// How a value was printed.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[repr(u8)]
pub enum Notation {
    Fixed = 0,
    ExpC = 1,
    ExpShort = 2,
    /// Kept as the characters themselves (in [`PrintedValues::verbatim`]).
    Verbatim = 3,
}

impl Notation {
    pub const ALL: [Notation; 4] = [
        Notation::Fixed,
        Notation::ExpC,
        Notation::ExpShort,
        Notation::Verbatim,
    ];

    pub fn from_u8(v: u8) -> Option<Notation> {
        Notation::ALL.get(usize::from(v)).copied()
    }
}

/// One printed value: `digits × 10^exp`, printed in `notation`. For a verbatim token,
/// `digits` is its index in the verbatim list.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct Printed {
    pub digits: i64,
    pub exp: i16,
    pub notation: Notation,
    /// A zero printed with a minus sign (`-0.0000`): kept, because it was printed.
    pub negative_zero: bool,
}

/// Every channel value of a take as printed, in file order, and the tokens kept verbatim.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct PrintedValues {
    pub values: Vec<Printed>,
    pub verbatim: Vec<String>,
}

impl PrintedValues {
    /// Add a token as read from a file.
    pub fn push_token(&mut self, token: &str) {
        let p = Printed::read(token).unwrap_or_else(|| {
            self.verbatim.push(token.to_string());
            Printed::verbatim(self.verbatim.len() - 1)
        });
        self.values.push(p);
    }

    /// Print value `i` into `out`.
    pub fn write(&self, i: usize, out: &mut String) {
        let p = self.values[i];
        match p.notation {
            Notation::Verbatim => out.push_str(
                usize::try_from(p.digits)
                    .ok()
                    .and_then(|k| self.verbatim.get(k))
                    .map_or("nan", String::as_str),
            ),
            _ => p.write(out),
        }
    }

    /// Value `i` as the f64 a reader parses from its characters.
    pub fn value(&self, i: usize) -> f64 {
        let p = self.values[i];
        match p.notation {
            Notation::Verbatim => usize::try_from(p.digits)
                .ok()
                .and_then(|k| self.verbatim.get(k))
                .and_then(|t| t.parse().ok())
                .unwrap_or(f64::NAN),
            _ => p.to_f64(),
        }
    }

    /// Append values `range` of `other`, its verbatim tokens with them (a range read
    /// gathers chunks decoded one by one).
    pub fn append(&mut self, other: PrintedValues, range: std::ops::Range<usize>) {
        let base = self.verbatim.len() as i64;
        self.verbatim.extend(other.verbatim);
        self.values
            .extend(other.values[range].iter().map(|v| match v.notation {
                Notation::Verbatim => Printed {
                    digits: v.digits + base,
                    ..*v
                },
                _ => *v,
            }));
    }

    /// Frames `start..end` of `channels`-wide rows.
    pub fn slice(&self, start: usize, end: usize, channels: usize) -> PrintedValues {
        PrintedValues {
            values: self.values[start * channels..end * channels].to_vec(),
            verbatim: self.verbatim.clone(),
        }
    }
}

impl Printed {
    pub fn verbatim(index: usize) -> Printed {
        Printed {
            digits: index as i64,
            exp: 0,
            notation: Notation::Verbatim,
            negative_zero: false,
        }
    }

    /// The token in one of the three notations, if it is printed exactly as [`Printed::write`]
    /// would print it.
    pub fn read(token: &str) -> Option<Printed> {
        let b = token.as_bytes();
        let (negative, rest) = match b.first()? {
            b'-' => (true, &b[1..]),
            _ => (false, b),
        };
        let int_len = rest.iter().take_while(|c| c.is_ascii_digit()).count();
        let mut pos = int_len;
        let mut frac_len = 0;
        if rest.get(pos) == Some(&b'.') {
            frac_len = rest[pos + 1..]
                .iter()
                .take_while(|c| c.is_ascii_digit())
                .count();
            pos += 1 + frac_len;
        }
        if int_len == 0 || int_len + frac_len > MAX_DIGITS {
            return None;
        }
        let frac_digits = if frac_len > 0 {
            &rest[int_len + 1..int_len + 1 + frac_len]
        } else {
            &[]
        };
        let mut digits: i64 = 0;
        for &c in rest[..int_len].iter().chain(frac_digits) {
            digits = digits * 10 + i64::from(c - b'0');
        }
        let frac = i16::try_from(frac_len).ok()?;
        let (exp, notation) = if pos == rest.len() {
            (-frac, Notation::Fixed)
        } else if rest[pos] == b'e' {
            let e = &token[token.len() - (rest.len() - pos - 1)..];
            let notation = if e.starts_with(['+', '-']) && e.len() >= 3 {
                Notation::ExpC
            } else {
                Notation::ExpShort
            };
            let value: i16 = e.parse().ok()?;
            (value.checked_sub(frac)?, notation)
        } else {
            return None;
        };
        let p = Printed {
            digits: if negative { -digits } else { digits },
            exp,
            notation,
            negative_zero: negative && digits == 0,
        };
        let mut again = String::with_capacity(token.len());
        p.write(&mut again);
        (again == token).then_some(p)
    }

    /// Print in this value's notation (not for [`Notation::Verbatim`]).
    pub fn write(&self, out: &mut String) {
        if self.digits < 0 || self.negative_zero {
            out.push('-');
        }
        let mut s = String::with_capacity(20);
        let _ = write!(s, "{}", self.digits.unsigned_abs());
        match self.notation {
            Notation::Fixed => {
                let decimals = (-i32::from(self.exp.min(0))) as usize;
                if self.exp > 0 {
                    out.push_str(&s);
                    out.extend(std::iter::repeat_n('0', self.exp as usize));
                } else if decimals == 0 {
                    out.push_str(&s);
                } else {
                    let padded = format!("{s:0>width$}", width = decimals + 1);
                    let (int, frac) = padded.split_at(padded.len() - decimals);
                    out.push_str(int);
                    out.push('.');
                    out.push_str(frac);
                }
            }
            Notation::ExpC | Notation::ExpShort => {
                let e = i32::from(self.exp) + s.len() as i32 - 1;
                out.push_str(&s[..1]);
                if s.len() > 1 {
                    out.push('.');
                    out.push_str(&s[1..]);
                }
                out.push('e');
                if self.notation == Notation::ExpC {
                    let _ = write!(out, "{}{:02}", if e < 0 { '-' } else { '+' }, e.abs());
                } else {
                    let _ = write!(out, "{e}");
                }
            }
            Notation::Verbatim => {}
        }
    }

    /// The f64 nearest `digits × 10^exp` — what parsing the printed characters gives.
    pub fn to_f64(&self) -> f64 {
        if self.negative_zero {
            return -0.0;
        }
        // Both operands exact and one correctly rounded operation: the correct parse.
        const POW10: [f64; 23] = [
            1e0, 1e1, 1e2, 1e3, 1e4, 1e5, 1e6, 1e7, 1e8, 1e9, 1e10, 1e11, 1e12, 1e13, 1e14, 1e15,
            1e16, 1e17, 1e18, 1e19, 1e20, 1e21, 1e22,
        ];
        let e = self.exp.unsigned_abs() as usize;
        if self.digits.unsigned_abs() < 1 << 53 && e < POW10.len() {
            let d = self.digits as f64;
            return if self.exp < 0 {
                d / POW10[e]
            } else {
                d * POW10[e]
            };
        }
        let mut s = String::with_capacity(32);
        let _ = write!(s, "{}e{}", self.digits, self.exp);
        s.parse().unwrap_or(f64::NAN)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_three_notations_print_back_the_same_characters() {
        for t in [
            "0",
            "-0",
            "12",
            "0.0000",
            "-0.0000",
            "-12.3456",
            "0.0012",
            "180.000000",
            "1500",
            "5.1072e-06",
            "-1e-05",
            "1.50000e+20",
            "3e-120",
            "1e-5",
            "-2.5e7",
            "1e0",
            "7e-10",
        ] {
            let p = Printed::read(t).unwrap_or_else(|| panic!("{t} not read"));
            assert_ne!(p.notation, Notation::Verbatim);
            let mut s = String::new();
            p.write(&mut s);
            assert_eq!(s, t);
            assert_eq!(
                p.to_f64().to_bits(),
                t.parse::<f64>().unwrap().to_bits(),
                "{t}"
            );
        }
        let p = Printed::read("-12.3456").unwrap();
        assert_eq!(
            (p.digits, p.exp, p.notation),
            (-123456, -4, Notation::Fixed)
        );
        let p = Printed::read("5.1072e-06").unwrap();
        assert_eq!((p.digits, p.exp, p.notation), (51072, -10, Notation::ExpC));
    }

    #[test]
    fn other_spellings_are_kept_verbatim() {
        for t in [
            "+1",
            ".5",
            "5.",
            "007",
            "1E5",
            "1e+5",
            "0.0e+00",
            "0.5e-3",
            "1e05",
            "1234567890123456789",
            "1.0e",
            "nan",
            "1e",
        ] {
            assert_eq!(Printed::read(t), None, "{t}");
        }
        let mut v = PrintedValues::default();
        for t in ["1.5", "+1", "-0.00"] {
            v.push_token(t);
        }
        let mut s = String::new();
        for i in 0..3 {
            v.write(i, &mut s);
            s.push(' ');
        }
        assert_eq!(s, "1.5 +1 -0.00 ");
        assert_eq!(v.value(1), 1.0);
        assert!(v.value(2).is_sign_negative());
    }

    #[test]
    fn values_beyond_the_exact_fast_path_still_parse_exactly() {
        for t in [
            "123456789012345678",
            "1.23456789012345e-300",
            "9.007199254740993e+30",
        ] {
            let p = Printed::read(t).unwrap();
            assert_eq!(p.to_f64(), t.parse::<f64>().unwrap(), "{t}");
        }
    }
}
