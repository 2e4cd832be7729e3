//! Small line charts as images, for coverage and network traffic over time: axes, grid
//! lines, tick labels in a built-in 3x5 pixel font (digits, `%`, `m` and `kB/s` only: every
//! label here is a number of minutes, a percentage or a data rate), and one polyline per
//! series.

use realms_core::{Grid, GridGeometry, Point2};

/// One line on a chart.
#[derive(Clone, Debug, PartialEq)]
pub struct Series {
    /// Line colour.
    pub color: [u8; 3],
    /// `(x, y)` points in data units, in x order.
    pub points: Vec<(f64, f64)>,
}

const WHITE: [u8; 3] = [255, 255, 255];
const AXIS: [u8; 3] = [60, 60, 60];
const GRID: [u8; 3] = [225, 225, 225];

/// Glyphs, 3 pixels wide and 5 tall, top row first, bit 2 the leftmost pixel.
fn glyph(c: char) -> Option<[u8; 5]> {
    Some(match c {
        '0' => [7, 5, 5, 5, 7],
        '1' => [2, 6, 2, 2, 7],
        '2' => [7, 1, 7, 4, 7],
        '3' => [7, 1, 7, 1, 7],
        '4' => [5, 5, 7, 1, 1],
        '5' => [7, 4, 7, 1, 7],
        '6' => [7, 4, 7, 5, 7],
        '7' => [7, 1, 2, 2, 2],
        '8' => [7, 5, 7, 5, 7],
        '9' => [7, 5, 7, 1, 7],
        '%' => [5, 1, 2, 4, 5],
        'm' => [0, 0, 6, 7, 5],
        'k' => [4, 5, 6, 5, 5],
        'B' => [6, 5, 6, 5, 6],
        's' => [0, 3, 6, 1, 6],
        '/' => [1, 1, 2, 4, 4],
        _ => return None,
    })
}

/// An image of `width` x `height` pixels (row 0 at the bottom, as [`Grid`] stores it).
struct Canvas {
    img: Grid<[u8; 3]>,
}

impl Canvas {
    fn new(width: usize, height: usize) -> Canvas {
        let geo = GridGeometry {
            width,
            height,
            resolution_m: 1.0,
            origin: Point2::new(0.0, 0.0),
        };
        Canvas {
            img: Grid::new(geo, WHITE),
        }
    }

    fn set(&mut self, x: i64, y: i64, c: [u8; 3]) {
        if x >= 0
            && y >= 0
            && let Some(p) = self.img.get_mut(x as usize, y as usize)
        {
            *p = c;
        }
    }

    fn line(&mut self, (x0, y0): (i64, i64), (x1, y1): (i64, i64), c: [u8; 3], thick: i64) {
        let n = (x1 - x0).abs().max((y1 - y0).abs()).max(1);
        for k in 0..=n {
            let x = x0 + (x1 - x0) * k / n;
            let y = y0 + (y1 - y0) * k / n;
            for dy in 0..thick {
                for dx in 0..thick {
                    self.set(x + dx - thick / 2, y + dy - thick / 2, c);
                }
            }
        }
    }

    /// Text with its lower-left corner at `(x, y)`, each font pixel `scale` pixels.
    fn text(&mut self, x: i64, y: i64, s: &str, scale: i64) {
        for (k, ch) in s.chars().enumerate() {
            let Some(rows) = glyph(ch) else { continue };
            for (r, bits) in rows.iter().enumerate() {
                for col in 0..3 {
                    if bits & (4 >> col) != 0 {
                        for dy in 0..scale {
                            for dx in 0..scale {
                                let px = x + (k as i64 * 4 + col) * scale + dx;
                                let py = y + (4 - r as i64) * scale + dy;
                                self.set(px, py, AXIS);
                            }
                        }
                    }
                }
            }
        }
    }
}

/// A chart of fractions (0..1, labelled in percent) against time in seconds (labelled in
/// minutes) up to `t_max_s`.
pub fn coverage_chart(series: &[Series], t_max_s: f64) -> Grid<[u8; 3]> {
    time_chart(
        series,
        t_max_s,
        YAxis {
            max: 1.0,
            label_scale: 100.0,
            unit: "%",
        },
    )
}

/// A chart of data rates in bytes per second (labelled in kB/s) against time.
pub fn rate_chart(series: &[Series], t_max_s: f64) -> Grid<[u8; 3]> {
    let peak = series
        .iter()
        .flat_map(|s| s.points.iter().map(|p| p.1))
        .fold(0.0f64, f64::max);
    // A round top in kB/s: 1, 2 or 5 times a power of ten.
    let kb = (peak / 1000.0).max(1.0);
    let decade = 10f64.powf(kb.log10().floor());
    let top = [1.0, 2.0, 5.0, 10.0]
        .into_iter()
        .map(|m| m * decade)
        .find(|t| *t >= kb)
        .unwrap_or(10.0 * decade);
    time_chart(
        series,
        t_max_s,
        YAxis {
            max: top * 1000.0,
            label_scale: 0.001,
            unit: "kB/s",
        },
    )
}

/// The vertical axis of a chart.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct YAxis {
    /// The value at the top.
    pub max: f64,
    /// Labels show values times this.
    pub label_scale: f64,
    /// And this after the number.
    pub unit: &'static str,
}

/// Lines of `series` against time in seconds (labelled in minutes) up to `t_max_s`.
pub fn time_chart(series: &[Series], t_max_s: f64, axis: YAxis) -> Grid<[u8; 3]> {
    let (w, h) = (800i64, 420i64);
    let widest_label = (0..=5)
        .map(|k| {
            let v = axis.max * k as f64 / 5.0;
            format!("{}{}", (v * axis.label_scale).round(), axis.unit).len() as i64
        })
        .max()
        .unwrap_or(4);
    let left = (22 + 12 * widest_label).max(70);
    let (bottom, right, top) = (50i64, 20i64, 20i64);
    let mut c = Canvas::new(w as usize, h as usize);
    let pw = (w - left - right) as f64;
    let ph = (h - bottom - top) as f64;
    let t_max = t_max_s.max(60.0);
    let y_max = if axis.max > 0.0 { axis.max } else { 1.0 };
    let to_px = |t: f64, v: f64| {
        (
            left + (t / t_max * pw).round() as i64,
            bottom + ((v / y_max).clamp(0.0, 1.0) * ph).round() as i64,
        )
    };
    // Grid lines every tenth, labels every fifth.
    for k in 0..=10 {
        let v = y_max * k as f64 / 10.0;
        let (_, y) = to_px(0.0, v);
        c.line((left, y), (w - right, y), GRID, 1);
        if k % 2 == 0 {
            let label = format!("{}{}", (v * axis.label_scale).round(), axis.unit);
            c.text(left - 10 - 12 * label.len() as i64, y - 7, &label, 3);
        }
    }
    // Time ticks at a round number of minutes, about eight of them.
    let minutes = t_max / 60.0;
    let step = [1.0, 2.0, 5.0, 10.0, 15.0, 30.0, 60.0, 120.0]
        .into_iter()
        .find(|s| minutes / s <= 8.0)
        .unwrap_or(240.0);
    let mut m = 0.0;
    while m <= minutes + 1e-9 {
        let (x, _) = to_px(m * 60.0, 0.0);
        c.line((x, bottom), (x, h - top), GRID, 1);
        let label = format!("{m:.0}m");
        c.text(x - 6 * label.len() as i64, bottom - 30, &label, 3);
        m += step;
    }
    c.line((left, bottom), (w - right, bottom), AXIS, 2);
    c.line((left, bottom), (left, h - top), AXIS, 2);
    for s in series {
        for pair in s.points.windows(2) {
            let a = to_px(pair[0].0, pair[0].1);
            let b = to_px(pair[1].0, pair[1].1);
            c.line(a, b, s.color, 3);
        }
    }
    c.img
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_rising_line_is_drawn_in_its_colour_from_the_origin_up() {
        let red = [230, 60, 50];
        let img = coverage_chart(
            &[Series {
                color: red,
                points: vec![(0.0, 0.0), (600.0, 1.0)],
            }],
            600.0,
        );
        // The line starts at the plot's origin and ends at its top-right corner.
        assert_eq!(img.get(70, 50), Some(&red));
        assert_eq!(img.get(780, 400), Some(&red));
        // Halfway along it is halfway up.
        assert_eq!(img.get(425, 225), Some(&red));
        // Nothing red below the line at its middle.
        assert_ne!(img.get(425, 150), Some(&red));
    }
}
