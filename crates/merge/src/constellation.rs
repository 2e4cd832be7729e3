//! Pose hypotheses from landmarks: rocks, boulders and crater rims taken as points with a
//! size, and translations voted for by every pair of landmarks of like size, one from each
//! map, at a few headings.
//!
//! The global search ([`crate::search`]) scores every translation on the maps' structure, and
//! at low overlap on lunar maps the walls dominate that score: a band across the hall whose
//! three rocks and a crater agree can rank below a dozen poses that lay walls over walls, and
//! never be verified. Where the rocks are the evidence, they can propose the pose
//! themselves: at the right heading every landmark the two maps share votes for the same
//! translation, while chance pairs scatter theirs over the whole hall (geometric hashing;
//! Lamdan and Wolfson 1988, "Geometric hashing: a general and efficient model-based
//! recognition scheme"). The headings come from the line-direction peaks, laid on the maps'
//! walls where they have them ([`crate::lines`]): a degree off, a landmark 20 m from the
//! map's origin votes 0.35 m astray.

use crate::level::{Class, Level};
use realms_core::geometry::CircleFit;
use realms_core::{Point2, Pose2};

/// A landmark: the centre and size of a blob of landmark cells.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Landmark {
    /// Centre of the circle fitted to the blob's outline where one fits
    /// (`circle_through`), else the centroid of its cells; grid-local metres.
    pub c: Point2,
    /// Radius of that circle, else of the disc of the blob's area; metres. The circle runs
    /// through the outline cells' centres, so for a solid blob it is about half a cell
    /// smaller than the area's disc: compare radii of one kind with a slack
    /// (`SIZE_SLACK_M`).
    pub radius_m: f64,
}

/// Blobs of fewer cells than this are no landmark: a speck, or a rock's corner cut by the
/// map's edge.
const MIN_CELLS: usize = 4;
/// Votes are binned on cells this large, metres: the blobs' centres move by a cell or two
/// with the cut and the noise.
const BIN_M: f64 = 0.4;
/// A translation needs this many votes (its bin and the eight around it) to be proposed.
const MIN_VOTES: usize = 3;
/// A translation bin, and its votes with the sum of their translations.
type Bin = (i64, i64);
type Tally = (usize, f64, f64);

/// Two landmarks are alike when their radii differ by at most this much, metres ...
const SIZE_SLACK_M: f64 = 0.1;
/// ... plus this share of the larger.
const SIZE_SLACK_SHARE: f64 = 0.25;
/// Landmarks at least this large (radius, metres) are large: craters and boulders, a few
/// in a hall.
const LARGE_M: f64 = 0.5;
/// A blob's outline is fitted with a circle only from this many points ...
const CIRCLE_MIN_POINTS: usize = 6;
/// ... and the circle kept where they lie within this much of it (cells, RMS) ...
const CIRCLE_RMS_CELLS: f64 = 1.0;
/// ... and it is at most this wide, metres (the default hall's largest crater is 6 m).
const CIRCLE_MAX_M: f64 = 8.0;
/// Proposals closer than this (metres, at the same heading) are one.
const DISTINCT_M: f64 = 1.0;

/// The landmarks of `level`: its landmark cells ([`Level::landmark`]) in 8-connected blobs.
pub fn landmarks(level: &Level) -> Vec<Landmark> {
    let (w, h) = (level.width, level.height);
    let is_landmark = |i: usize| level.class[i] != Class::Unknown && level.landmark[i];
    let mut seen = vec![false; w * h];
    let mut out = Vec::new();
    let mut stack = Vec::new();
    let mut outline = Vec::new();
    for start in 0..w * h {
        if seen[start] || !is_landmark(start) {
            continue;
        }
        seen[start] = true;
        stack.push(start);
        let (mut n, mut sx, mut sy) = (0usize, 0.0, 0.0);
        outline.clear();
        while let Some(i) = stack.pop() {
            let (x, y) = (i % w, i / w);
            let c = level.center(x, y);
            n += 1;
            sx += c.x_m;
            sy += c.y_m;
            let (xi, yi) = (x as i64, y as i64);
            if [(1, 0), (-1, 0), (0, 1), (0, -1)]
                .iter()
                .any(|(dx, dy)| level.class_at(xi + dx, yi + dy) == Class::Free)
            {
                outline.push(c);
            }
            for dy in -1i64..=1 {
                for dx in -1i64..=1 {
                    let (nx, ny) = (x as i64 + dx, y as i64 + dy);
                    if nx < 0 || ny < 0 || nx >= w as i64 || ny >= h as i64 {
                        continue;
                    }
                    let j = ny as usize * w + nx as usize;
                    if !seen[j] && is_landmark(j) {
                        seen[j] = true;
                        stack.push(j);
                    }
                }
            }
        }
        if n >= MIN_CELLS {
            let area = n as f64 * level.cell_m * level.cell_m;
            let blob = Landmark {
                c: Point2::new(sx / n as f64, sy / n as f64),
                radius_m: (area / std::f64::consts::PI).sqrt(),
            };
            out.push(circle_through(&outline, level.cell_m).unwrap_or(blob));
        }
    }
    out
}

/// The circle through `outline` (the cells of a blob that face free ground), where it fits
/// them within [`CIRCLE_RMS_CELLS`] and is at most [`CIRCLE_MAX_M`] across: a crater cut by
/// the map's edge keeps its own centre and size, where its blob's centroid and area would
/// shrink towards the part in view. The algebraic fit of Kasa ([`CircleFit`]).
fn circle_through(outline: &[Point2], cell_m: f64) -> Option<Landmark> {
    if outline.len() < CIRCLE_MIN_POINTS {
        return None;
    }
    let fit = CircleFit::of(outline)?;
    let radius_m = fit.radius_m;
    let rms = fit.rms_off_m(outline);
    (radius_m <= CIRCLE_MAX_M / 2.0 && rms <= CIRCLE_RMS_CELLS * cell_m).then(|| Landmark {
        c: fit.centre(),
        radius_m,
    })
}

/// Whether two landmarks are of like size ([`SIZE_SLACK_M`], [`SIZE_SLACK_SHARE`]).
fn alike(la: &Landmark, lb: &Landmark) -> bool {
    let slack = SIZE_SLACK_M + SIZE_SLACK_SHARE * la.radius_m.max(lb.radius_m);
    (la.radius_m - lb.radius_m).abs() <= slack
}

/// A slide along the walls is put on a landmark pair only where the pair asks for at most
/// this much across them, metres: the walls fix that offset to a cell or two.
const SLIDE_ACROSS_M: f64 = 0.3;
/// ... and for at least this much along them (less is the pose itself).
const SLIDE_ALONG_M: f64 = 0.5;

/// Poses `pose` slid along its walls (direction `along_rad`, grid-local in `a`) to lay a
/// landmark of `b` on a like-sized one of `a`: at most `max`, those whose pairs ask least
/// across the walls first.
///
/// A band from wall to wall with a single rock in it is held across the walls and in
/// heading by them, and along them by the rock alone. The global search, on cells too
/// coarse for a small rock, finds the band slid along the walls to where its points fall
/// on other structure; one rock proposes nothing in [`hypotheses`], which needs three
/// votes. Chance pairs ask for offsets across the walls spread over the whole hall, so
/// few pass the gate, and the verification judges those that do.
pub fn slides(
    a: &[Landmark],
    b: &[Landmark],
    pose: &Pose2,
    along_rad: f64,
    max: usize,
) -> Vec<Pose2> {
    let (s, c) = pose.yaw_rad.sin_cos();
    let (us, uc) = along_rad.sin_cos();
    let mut found: Vec<(f64, Pose2)> = Vec::new();
    for la in a {
        for lb in b.iter().filter(|lb| alike(la, lb)) {
            let dx = la.c.x_m - (c * lb.c.x_m - s * lb.c.y_m + pose.x_m);
            let dy = la.c.y_m - (s * lb.c.x_m + c * lb.c.y_m + pose.y_m);
            let along = dx * uc + dy * us;
            let across = -dx * us + dy * uc;
            if across.abs() <= SLIDE_ACROSS_M && along.abs() >= SLIDE_ALONG_M {
                let slid = Pose2::new(pose.x_m + along * uc, pose.y_m + along * us, pose.yaw_rad);
                found.push((across.abs(), slid));
            }
        }
    }
    found.sort_by(|x, y| x.0.total_cmp(&y.0));
    first_distinct(found.into_iter().map(|(_, p)| p), max)
}

/// At most `max` poses per heading (grid-local, of `b` in `a`) that several landmark pairs
/// of like size agree on, at the headings `yaws_rad`, the most voted first at each.
pub fn hypotheses(a: &[Landmark], b: &[Landmark], yaws_rad: &[f64], max: usize) -> Vec<Pose2> {
    let mut proposals: Vec<Pose2> = Vec::new();
    for &yaw in yaws_rad {
        let (s, c) = yaw.sin_cos();
        let mut votes: Vec<(Bin, usize, f64, f64)> = Vec::new();
        for la in a {
            for lb in b {
                if !alike(la, lb) {
                    continue;
                }
                let tx = la.c.x_m - (c * lb.c.x_m - s * lb.c.y_m);
                let ty = la.c.y_m - (s * lb.c.x_m + c * lb.c.y_m);
                let key = ((tx / BIN_M).floor() as i64, (ty / BIN_M).floor() as i64);
                // Two large landmarks alike (a crater, a boulder) are rare enough to count
                // as much as a proposal needs on their own.
                let weight = if la.radius_m.min(lb.radius_m) >= LARGE_M {
                    MIN_VOTES
                } else {
                    1
                };
                votes.push((key, weight, tx * weight as f64, ty * weight as f64));
            }
        }
        // Per bin, in order: votes and the sum of their translations.
        votes.sort_unstable_by_key(|v| v.0);
        let mut bins: Vec<(Bin, Tally)> = Vec::new();
        for (key, weight, tx, ty) in votes {
            match bins.last_mut() {
                Some((k, (n, sx, sy))) if *k == key => {
                    *n += weight;
                    *sx += tx;
                    *sy += ty;
                }
                _ => bins.push((key, (weight, tx, ty))),
            }
        }
        let mut found: Vec<(usize, Pose2)> = Vec::new();
        for &((kx, ky), _) in &bins {
            let (mut n, mut sx, mut sy) = (0usize, 0.0, 0.0);
            for dy in -1..=1 {
                for dx in -1..=1 {
                    if let Ok(i) = bins.binary_search_by_key(&(kx + dx, ky + dy), |b| b.0) {
                        let (bn, bx, by) = bins[i].1;
                        n += bn;
                        sx += bx;
                        sy += by;
                    }
                }
            }
            if n >= MIN_VOTES {
                found.push((n, Pose2::new(sx / n as f64, sy / n as f64, yaw)));
            }
        }
        // The most voted first, ties by place.
        found.sort_by(|x, y| {
            y.0.cmp(&x.0)
                .then(x.1.x_m.total_cmp(&y.1.x_m))
                .then(x.1.y_m.total_cmp(&y.1.y_m))
        });
        // The `max` most voted distinct ones at this heading.
        proposals.extend(first_distinct(found.into_iter().map(|(_, p)| p), max));
    }
    // Heading by heading: a crater votes as well for its own pose turned half a turn, and
    // which of the two is right is for the screening to say.
    proposals
}

/// The first `max` of `poses` (all at one heading) that lie [`DISTINCT_M`] or more from
/// every one kept before them.
fn first_distinct(poses: impl Iterator<Item = Pose2>, max: usize) -> Vec<Pose2> {
    let mut kept: Vec<Pose2> = Vec::with_capacity(max);
    for p in poses {
        if kept.len() >= max {
            break;
        }
        if !kept
            .iter()
            .any(|q| (q.x_m - p.x_m).hypot(q.y_m - p.y_m) < DISTINCT_M)
        {
            kept.push(p);
        }
    }
    kept
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::map::{Map, MapCell};
    use realms_core::{Grid, GridGeometry};

    #[test]
    fn rocks_are_found_where_they_lie_and_as_large() {
        // Two rocks on a 5 cm floor, 0.3 m and 0.6 m across: on the 10 cm level, blobs
        // centred on them, of about their size.
        let g = GridGeometry {
            width: 200,
            height: 200,
            resolution_m: 0.05,
            origin: Point2::new(0.0, 0.0),
        };
        let rocks = [(3.0, 4.0, 0.15), (7.0, 6.0, 0.3)];
        let mut grid = Grid::new(g, MapCell::Free);
        for y in 0..200 {
            for x in 0..200 {
                let p = g.cell_center(realms_core::Cell { x, y });
                if rocks
                    .iter()
                    .any(|&(rx, ry, r)| (p.x_m - rx).hypot(p.y_m - ry) < r)
                {
                    *grid.get_mut(x, y).expect("in the grid") = MapCell::Occupied;
                }
            }
        }
        let found = landmarks(&Level::build(&Map::new(grid), 0.1));
        assert_eq!(found.len(), 2, "{found:?}");
        for &(rx, ry, r) in &rocks {
            let l = found
                .iter()
                .find(|l| l.c.distance_m(Point2::new(rx, ry)) < 0.1)
                .unwrap_or_else(|| panic!("no landmark at ({rx}, {ry}): {found:?}"));
            assert!((l.radius_m - r).abs() < 0.08, "{l:?} against {r}");
        }
    }

    #[test]
    fn a_crater_cut_by_the_map_s_edge_keeps_its_centre_and_size() {
        // A crater 4 m across (hazard) at (5, 5), the map ending at x = 5.5 m: its blob's
        // centroid lies near (4.3, 5), its circle at the crater's own centre.
        let g = GridGeometry {
            width: 200,
            height: 200,
            resolution_m: 0.05,
            origin: Point2::new(0.0, 0.0),
        };
        let mut grid = Grid::new(g, MapCell::Free);
        for y in 0..200 {
            for x in 0..200 {
                let p = g.cell_center(realms_core::Cell { x, y });
                let cell = if p.x_m > 5.5 {
                    MapCell::Unknown
                } else if (p.x_m - 5.0).hypot(p.y_m - 5.0) < 2.0 {
                    MapCell::Hazard
                } else {
                    MapCell::Free
                };
                *grid.get_mut(x, y).expect("in the grid") = cell;
            }
        }
        let found = landmarks(&Level::build(&Map::new(grid), 0.1));
        assert_eq!(found.len(), 1, "{found:?}");
        let crater = found[0];
        assert!(
            crater.c.distance_m(Point2::new(5.0, 5.0)) < 0.1,
            "{crater:?}"
        );
        assert!((crater.radius_m - 2.0).abs() < 0.1, "{crater:?}");
    }

    #[test]
    fn a_band_slid_along_its_walls_is_put_back_on_its_one_rock() {
        // Rocks across a 50 x 36 m hall; the second map holds one of them, seen from a
        // frame turned a quarter and shifted, and two of its own. The pose to slide is the
        // truth moved 6 m along the walls running along x (and 5 cm across them, as a
        // coarse search leaves it).
        let a: Vec<Landmark> = (0..30)
            .map(|k| Landmark {
                c: Point2::new(1.7 * k as f64 % 50.0, (5.3 * k as f64) % 36.0),
                radius_m: 0.15 + 0.01 * (k % 5) as f64,
            })
            .collect();
        let truth = Pose2::new(20.0, 8.0, std::f64::consts::FRAC_PI_2);
        let shared = a[7];
        let mut b = vec![Landmark {
            c: truth.inverse().transform_point(shared.c),
            ..shared
        }];
        b.push(Landmark {
            c: Point2::new(3.0, -2.0),
            radius_m: 0.16,
        });
        b.push(Landmark {
            c: Point2::new(-4.0, 1.5),
            radius_m: 0.9,
        });
        let slid = Pose2::new(truth.x_m + 6.0, truth.y_m + 0.05, truth.yaw_rad);
        let found = slides(&a, &b, &slid, 0.0, 4);
        assert!(
            found.iter().any(|p| (p.x_m - truth.x_m).abs() < 1e-9
                && (p.y_m - slid.y_m).abs() < 1e-9
                && p.yaw_rad == truth.yaw_rad),
            "{found:?}"
        );
        // Along the other walls (y) the rock asks for a slide across them: nothing from it.
        let found = slides(&a, &b[..1], &slid, std::f64::consts::FRAC_PI_2, 4);
        assert!(
            found.iter().all(|p| (p.x_m - truth.x_m).abs() > 1.0),
            "{found:?}"
        );
        // Chance pairs pass the gate only where they happen to lie across the walls as the
        // pose does: never more than asked for.
        assert!(slides(&a, &b, &slid, 0.0, 2).len() <= 2);
    }

    #[test]
    fn the_shared_rocks_vote_for_the_true_pose_among_chance_pairs() {
        // Forty rocks of a few sizes in the first map; the second map holds five of them
        // seen from a frame turned and shifted, and twenty of its own.
        let mut seed = 7u64;
        let mut next = || {
            seed = seed
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (seed >> 11) as f64 / (1u64 << 53) as f64
        };
        let rock = |next: &mut dyn FnMut() -> f64| Landmark {
            c: Point2::new(50.0 * next(), 36.0 * next()),
            radius_m: 0.1 + 0.3 * next(),
        };
        let a: Vec<Landmark> = (0..40).map(|_| rock(&mut next)).collect();
        let truth = Pose2::new(12.0, -3.0, 0.7);
        let b_from_a = truth.inverse();
        let mut b: Vec<Landmark> = a[..5]
            .iter()
            .map(|l| Landmark {
                c: b_from_a.transform_point(l.c),
                ..*l
            })
            .collect();
        b.extend((0..20).map(|_| rock(&mut next)));
        // At the true heading the most voted proposal is the truth; among three headings it
        // is proposed too.
        let found = hypotheses(&a, &b, &[0.2, truth.yaw_rad, 2.5], 3);
        assert!(
            found.iter().any(|p| p.yaw_rad == truth.yaw_rad
                && (p.x_m - truth.x_m).hypot(p.y_m - truth.y_m) < 0.2),
            "{found:?}"
        );
        let found = hypotheses(&a, &b, &[truth.yaw_rad], 3);
        let best = found.first().expect("a proposal");
        assert!(
            // Within half a bin: the chance votes around it pull the mean a little, and
            // refinement takes it from there.
            (best.x_m - truth.x_m).hypot(best.y_m - truth.y_m) < 0.2
                && best.yaw_rad == truth.yaw_rad,
            "{found:?}"
        );
        // One large crater shared, its like nowhere else: proposed on its own.
        let crater = Landmark {
            c: Point2::new(20.0, 10.0),
            radius_m: 1.5,
        };
        let seen = Landmark {
            c: b_from_a.transform_point(crater.c),
            ..crater
        };
        let found = hypotheses(&[&a[..], &[crater]].concat(), &[seen], &[truth.yaw_rad], 3);
        assert!(
            found
                .iter()
                .any(|p| (p.x_m - truth.x_m).hypot(p.y_m - truth.y_m) < 0.01),
            "{found:?}"
        );
        // Without the shared rocks, no heading gathers as many votes in one place.
        let strangers: Vec<Landmark> = b[5..].to_vec();
        let found = hypotheses(&a, &strangers, &[truth.yaw_rad], 3);
        assert!(
            found
                .iter()
                .all(|p| (p.x_m - truth.x_m).hypot(p.y_m - truth.y_m) > 1.0),
            "{found:?}"
        );
    }
}
