//! Heading candidates from the direction of structure: the histogram of local line
//! directions of each map, circularly cross-correlated, peaks at the relative heading (mod
//! 180 degrees). This is the rotation half of Carpin's spectra-based merging ("Fast and
//! accurate map merging for multi-robot systems", Autonomous Robots 25, 2008), with line
//! directions taken from the local covariance of structure cells instead of a Hough
//! transform, weighted by how line-like the neighbourhood is (a boulder votes for nothing).

use crate::level::{Level, local_shape};

/// Histogram bins over 180 degrees.
pub const BINS: usize = 180;

/// A line-direction histogram, bins of one degree over [0, 180).
#[derive(Clone, Debug)]
pub struct Directions {
    /// Weights per bin, smoothed.
    pub bins: Vec<f64>,
}

impl Directions {
    /// The histogram of `level`'s structure.
    pub fn of(level: &Level) -> Directions {
        let mut bins = vec![0.0; BINS];
        let (w, h) = (level.width as i64, level.height as i64);
        const R: i64 = 4;
        for y in 0..h {
            for x in 0..w {
                if !level.class_at(x, y).is_feature() {
                    continue;
                }
                let feature = |fx: i64, fy: i64| level.class_at(fx, fy).is_feature();
                let Some((n, coherence, angle)) = local_shape(feature, x, y, R) else {
                    continue;
                };
                if n < 3.0 {
                    continue;
                }
                let deg = angle.to_degrees().rem_euclid(180.0);
                let weight = coherence * coherence;
                // Split the vote between the two nearest bins.
                let lo = deg.floor();
                let frac = deg - lo;
                let i = lo as usize % BINS;
                bins[i] += weight * (1.0 - frac);
                bins[(i + 1) % BINS] += weight * frac;
            }
        }
        // Smooth with a [1 2 1] kernel, twice: staircased diagonals scatter a degree or two.
        for _ in 0..2 {
            let b = bins.clone();
            for i in 0..BINS {
                bins[i] = 0.25 * b[(i + BINS - 1) % BINS] + 0.5 * b[i] + 0.25 * b[(i + 1) % BINS];
            }
        }
        Directions { bins }
    }

    /// Total weight: how much line-like structure there is.
    pub fn total(&self) -> f64 {
        self.bins.iter().sum()
    }
}

/// Relative heading candidates of `moving` in `fixed`, degrees in [0, 180), best first: the
/// highest peaks of the circular cross-correlation, at least `separation_deg` apart, and
/// the peak-to-mean ratio of the correlation (near 1 when the directions say nothing).
pub fn candidates(
    fixed: &Directions,
    moving: &Directions,
    count: usize,
    separation_deg: usize,
) -> (Vec<f64>, f64) {
    let corr: Vec<f64> = (0..BINS)
        .map(|shift| {
            (0..BINS)
                .map(|i| moving.bins[i] * fixed.bins[(i + shift) % BINS])
                .sum()
        })
        .collect();
    let mean = corr.iter().sum::<f64>() / BINS as f64;
    let mut order: Vec<usize> = (0..BINS).collect();
    order.sort_by(|a, b| corr[*b].total_cmp(&corr[*a]).then(a.cmp(b)));
    let mut peaks: Vec<usize> = Vec::new();
    for i in order {
        if peaks.len() >= count {
            break;
        }
        let circ = |a: usize, b: usize| {
            let d = a.abs_diff(b);
            d.min(BINS - d)
        };
        if peaks.iter().all(|p| circ(*p, i) >= separation_deg) {
            peaks.push(i);
        }
    }
    let peak = peaks.first().map_or(0.0, |p| corr[*p]);
    let ratio = if mean > 0.0 { peak / mean } else { 1.0 };
    // Refine each peak to a fraction of a degree with a parabola through its neighbours.
    let refined = peaks
        .iter()
        .map(|&i| {
            let (l, c, r) = (corr[(i + BINS - 1) % BINS], corr[i], corr[(i + 1) % BINS]);
            let den = l - 2.0 * c + r;
            let off = if den < 0.0 {
                (0.5 * (l - r) / den).clamp(-0.5, 0.5)
            } else {
                0.0
            };
            (i as f64 + off).rem_euclid(180.0)
        })
        .collect();
    (refined, ratio)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::map::{Map, MapCell};
    use realms_core::{Grid, GridGeometry, Point2};

    /// Two long walls at `deg` and `deg + 90` through the middle of a 200 x 200 grid.
    fn cross(deg: f64) -> Map {
        let g = GridGeometry {
            width: 200,
            height: 200,
            resolution_m: 0.1,
            origin: Point2::new(0.0, 0.0),
        };
        let mut grid = Grid::new(g, MapCell::Free);
        for k in 0..2 {
            let a = (deg + 90.0 * k as f64).to_radians();
            for s in -800..800 {
                let t = s as f64 / 10.0;
                let (x, y) = (100.0 + t * a.cos(), 100.0 + t * a.sin());
                if let Some(c) = grid.get_mut(x as usize, y as usize) {
                    *c = MapCell::Occupied;
                }
            }
        }
        Map::new(grid)
    }

    #[test]
    fn relative_heading_is_a_peak() {
        let a = Directions::of(&Level::build(&cross(10.0), 0.1));
        let b = Directions::of(&Level::build(&cross(35.0), 0.1));
        let (peaks, ratio) = candidates(&a, &b, 3, 5);
        assert!(ratio > 2.0, "{ratio}");
        // B's walls must turn by -25 degrees (mod 90 for a cross) to lie on A's.
        let hit = peaks.iter().any(|p| {
            let d = (p - 155.0).rem_euclid(90.0);
            d.min(90.0 - d) < 1.5
        });
        assert!(hit, "{peaks:?}");
    }
}
