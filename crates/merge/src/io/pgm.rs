//! Netpbm grayscale images (PGM): binary `P5` (8- or 16-bit) and plain-text `P2`, the image
//! half of a ROS map_server map. Every malformed header or short pixel block is an error
//! saying what was expected; nothing here panics on bad bytes.

/// A decoded image: `width * height` samples, rows top-down (image order).
#[derive(Clone, Debug, PartialEq)]
pub struct Pgm {
    /// Columns.
    pub width: usize,
    /// Rows.
    pub height: usize,
    /// Largest sample value the file declares (1..=65535).
    pub max_value: u16,
    /// Samples, row by row from the top.
    pub samples: Vec<u16>,
}

/// Largest image accepted, in pixels: 100 M, far beyond any map yet small enough that a
/// corrupt header cannot make us allocate gigabytes.
const MAX_PIXELS: usize = 100_000_000;

/// Reads header tokens, skipping whitespace and `#` comments.
struct Header<'a> {
    bytes: &'a [u8],
    pos: usize,
}

impl Header<'_> {
    fn token(&mut self, what: &str) -> Result<&[u8], String> {
        loop {
            match self.bytes.get(self.pos) {
                Some(b'#') => {
                    while self.bytes.get(self.pos).is_some_and(|b| *b != b'\n') {
                        self.pos += 1;
                    }
                }
                Some(b) if b.is_ascii_whitespace() => self.pos += 1,
                Some(_) => break,
                None => return Err(format!("file ends before the {what}")),
            }
        }
        let start = self.pos;
        while self
            .bytes
            .get(self.pos)
            .is_some_and(|b| !b.is_ascii_whitespace() && *b != b'#')
        {
            self.pos += 1;
        }
        Ok(&self.bytes[start..self.pos])
    }

    fn number(&mut self, what: &str) -> Result<usize, String> {
        let t = self.token(what)?;
        std::str::from_utf8(t)
            .ok()
            .and_then(|s| s.parse::<usize>().ok())
            .ok_or_else(|| {
                format!(
                    "expected the {what} as a whole number, found `{}`",
                    String::from_utf8_lossy(t)
                )
            })
    }
}

/// Decodes a PGM file's bytes.
pub fn decode(bytes: &[u8]) -> Result<Pgm, String> {
    let mut h = Header { bytes, pos: 0 };
    let magic = h.token("magic number")?;
    let binary = match magic {
        b"P5" => true,
        b"P2" => false,
        other => {
            return Err(format!(
                "expected a grayscale PGM (magic `P5` or `P2`), found `{}`",
                String::from_utf8_lossy(&other[..other.len().min(8)])
            ));
        }
    };
    let width = h.number("width")?;
    let height = h.number("height")?;
    let max_value = h.number("maximum value")?;
    if width == 0 || height == 0 {
        return Err(format!("image is empty ({width} x {height})"));
    }
    let pixels = width
        .checked_mul(height)
        .filter(|n| *n <= MAX_PIXELS)
        .ok_or_else(|| format!("image too large ({width} x {height})"))?;
    let max_value = u16::try_from(max_value)
        .ok()
        .filter(|m| *m >= 1)
        .ok_or_else(|| format!("maximum value must be 1..=65535, found {max_value}"))?;
    let mut samples = Vec::with_capacity(pixels);
    if binary {
        // Exactly one whitespace byte separates the header from the pixels.
        let start = h.pos + 1;
        let per = if max_value > 255 { 2 } else { 1 };
        let need = pixels * per;
        let data = bytes.get(start..).unwrap_or(&[]);
        if data.len() < need {
            return Err(format!(
                "pixel data too short: {width} x {height} needs {need} bytes, found {}",
                data.len()
            ));
        }
        if per == 1 {
            samples.extend(data[..need].iter().map(|b| *b as u16));
        } else {
            samples.extend(
                data[..need]
                    .chunks_exact(2)
                    .map(|b| u16::from_be_bytes([b[0], b[1]])),
            );
        }
    } else {
        for i in 0..pixels {
            let v = h
                .number("pixel value")
                .map_err(|e| format!("pixel {i} of {pixels}: {e}"))?;
            samples.push(v.min(u16::MAX as usize) as u16);
        }
    }
    if let Some(bad) = samples.iter().find(|s| **s > max_value) {
        return Err(format!(
            "pixel value {bad} exceeds the declared maximum {max_value}"
        ));
    }
    Ok(Pgm {
        width,
        height,
        max_value,
        samples,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn decodes_binary_and_plain_with_comments() {
        let mut p5 = b"P5\n# made by hand\n3 2\n255\n".to_vec();
        p5.extend([0, 205, 254, 1, 2, 3]);
        let img = decode(&p5).expect("valid P5");
        assert_eq!((img.width, img.height, img.max_value), (3, 2, 255));
        assert_eq!(img.samples, vec![0, 205, 254, 1, 2, 3]);
        let p2 = decode(b"P2 3 2 255\n0 205 254\n# row 2\n1 2 3\n").expect("valid P2");
        assert_eq!(p2.samples, img.samples);
        let mut wide = b"P5 1 1 65535\n".to_vec();
        wide.extend([0x01, 0x02]);
        assert_eq!(decode(&wide).expect("16 bit").samples, vec![0x0102]);
    }

    #[test]
    fn bad_images_say_what_is_wrong() {
        assert!(
            decode(b"P6 1 1 255\n\0\0\0")
                .expect_err("colour")
                .contains("P5")
        );
        assert!(
            decode(b"P5 3 2 255\n\0\0")
                .expect_err("short")
                .contains("too short")
        );
        assert!(
            decode(b"P5 x 2 255\n")
                .expect_err("width")
                .contains("width")
        );
        assert!(
            decode(b"P5 0 2 255\n")
                .expect_err("empty")
                .contains("empty")
        );
        assert!(
            decode(b"P5 99999 99999 255\n")
                .expect_err("huge")
                .contains("large")
        );
        assert!(
            decode(b"P2 2 1 100\n5 101\n")
                .expect_err("over max")
                .contains("exceeds")
        );
        assert!(
            decode(b"P2 2 1 255\n5\n")
                .expect_err("missing")
                .contains("pixel 1")
        );
        assert!(decode(b"").expect_err("nothing").contains("magic"));
    }
}
