//! Decimal numbers of text tables (TRC cells), parsed with the bits of `str::parse::<f64>`.
//!
//! Marker exports write plain decimals (`-130.534315`): at most 19 digits, a few after the
//! point. For those, the value is the exact integer of its digits divided by an exact power of
//! ten, one correctly rounded IEEE division (Clinger's fast path, the one the standard library
//! takes for them too), so the result is the standard library's bit for bit. Anything else
//! (exponents, `inf`, long mantissas, stray characters) goes to `str::parse`.

/// Powers of ten exactly representable as `f64` (10²² is the largest).
const POW10: [f64; 23] = [
    1e0, 1e1, 1e2, 1e3, 1e4, 1e5, 1e6, 1e7, 1e8, 1e9, 1e10, 1e11, 1e12, 1e13, 1e14, 1e15, 1e16, 1e17, 1e18, 1e19, 1e20,
    1e21, 1e22,
];

/// `s.parse::<f64>().ok()`, bit for bit, with a fast path for plain decimals.
#[inline]
pub fn parse_f64(s: &str) -> Option<f64> {
    plain(s.as_bytes()).or_else(|| s.parse::<f64>().ok())
}

/// `[+-]?digits[.digits]` (at least one digit) whose digits make an integer of at most 2⁵³ with
/// at most 22 after the point; `None` for anything else.
#[inline]
fn plain(b: &[u8]) -> Option<f64> {
    let (neg, mut i) = match b.first() {
        Some(b'-') => (true, 1),
        Some(b'+') => (false, 1),
        _ => (false, 0),
    };
    let (mut m, mut digits, mut frac) = (0u64, 0usize, None::<usize>);
    while i < b.len() {
        let c = b[i];
        if c.is_ascii_digit() {
            digits += 1;
            if digits > 19 {
                return None;
            }
            m = m * 10 + u64::from(c - b'0');
        } else if c == b'.' && frac.is_none() {
            frac = Some(digits);
        } else {
            return None;
        }
        i += 1;
    }
    let e = digits - frac.unwrap_or(digits);
    if digits == 0 || m > 1 << 53 || e >= POW10.len() {
        return None;
    }
    let v = m as f64 / POW10[e];
    Some(if neg { -v } else { v })
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{RngExt, SeedableRng};

    fn same(s: &str) {
        let ours = parse_f64(s).map(f64::to_bits);
        let std = s.parse::<f64>().ok().map(f64::to_bits);
        assert_eq!(ours, std, "{s:?}");
    }

    #[test]
    fn plain_decimals_parse_to_the_standard_librarys_bits() {
        for s in [
            "0",
            "-0",
            "+0",
            "-0.000",
            "0.",
            ".5",
            "-.5",
            "1.",
            "10051.425078",
            "-130.534315",
            "9007199254740992",
            "9007199254740993",
            "0.1",
            "0.3",
            "123456789012345678",
            "1234567890123456789",
            "12345678901234567890",
            "0.0000000000000000000001",
            "0.00000000000000000000001",
            "1e5",
            "-1E-3",
            "inf",
            "NaN",
            "nan",
            "",
            "-",
            "+",
            ".",
            "-.",
            "1.2.3",
            "1-2",
            " 1",
            "1 ",
            "0x10",
            "1_000",
            "١",
        ] {
            same(s);
        }
    }

    #[test]
    fn random_decimals_parse_to_the_standard_librarys_bits() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(22);
        for _ in 0..200_000 {
            let int_digits = rng.random_range(0..12);
            let frac_digits = rng.random_range(0..12);
            let mut s = String::new();
            match rng.random_range(0..4) {
                0 => s.push('-'),
                1 => s.push('+'),
                _ => {}
            }
            for _ in 0..int_digits {
                s.push(char::from(b'0' + rng.random_range(0..10u8)));
            }
            if frac_digits > 0 || rng.random_bool(0.1) {
                s.push('.');
            }
            for _ in 0..frac_digits {
                s.push(char::from(b'0' + rng.random_range(0..10u8)));
            }
            same(&s);
            // The values TRC writers print.
            let x: f64 = rng.random_range(-2.0e4..2.0e4);
            same(&format!("{x:.6}"));
            same(&format!("{x:.3}"));
            same(&format!("{x}"));
        }
    }
}
