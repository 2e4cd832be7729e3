//! The two walks of a cast: the clearance walk through open space, one step per call (every
//! cast takes it), and the short near walk from a start known to be clear, run cell by cell
//! until it settles (image pixels take it from where their fan's profile stops them, see
//! `fan.rs`; every cast takes it where the clearance field hands over).
//!
//! Each clearance step is a short chain of dependent arithmetic and one load, so the lidar's
//! beams are walked eight side by side ([`HeightPyramid::cast_side_by_side`]): the core
//! overlaps their chains, and a scan takes about a quarter less time (BENCHMARKS.md,
//! twenty-fifth session). The near walks of image pixels are a few cells each; stepping those
//! side by side was slower than one after the other.

use super::{CLEAR_BLOCK, Clearance, HeightPyramid, Level, exit_time, step_sign};

/// Sphere tracing through the clearance field (see [`HeightPyramid::cast`]), one step per
/// [`HeightPyramid::clear_step`].
#[derive(Clone, Copy, Debug)]
pub(super) struct ClearWalk {
    origin: [f64; 3],
    dir: [f64; 3],
    /// Cells crossed per unit of t along the axis the ray moves most on: the clearance field
    /// holds chessboard distances, so a step may go that far along that axis, up to 41 %
    /// further than the same distance taken as a length (diagonal rays).
    cells_per_t: f64,
    t_per_cell: f64,
    t_per_drop_m: f64,
    inv_res: f64,
    inv_dz: f64,
    /// Layers below the ray's height the step reads: one for a falling ray (so it may drop
    /// a layer's spacing before the step must end), none for one that never falls (it stays
    /// above the layer at its own height: fewer cells reach it, so the steps are longer).
    layers_below: f64,
    t: f64,
    t_max: f64,
}

/// What one step of a clearance walk ended with.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) enum ClearStep {
    /// Moved on through open space.
    Open,
    /// Can prove no further: exact marching takes over from this t.
    Exact(f64),
    /// Reached `t_max` through open space.
    Clear,
}

/// Level-0 cells walked for a short stretch from a proved start (see `fan.rs`), walked by
/// [`HeightPyramid::near_run`].
#[derive(Clone, Copy, Debug)]
pub(super) struct NearWalk {
    origin_z: f64,
    dz: f64,
    cx: i64,
    cy: i64,
    step_x: i64,
    step_y: i64,
    tdx: f64,
    tdy: f64,
    tmx: f64,
    tmy: f64,
    t: f64,
    t_max: f64,
    cells_left: usize,
}

impl NearWalk {
    /// Lets a walk that settled on its `t_max` with no hit go on, to `t_max` further out. The
    /// cells it has left to walk are not renewed: past them it hands over to a full cast.
    pub(super) fn extend_to(&mut self, t_max: f64) {
        self.t_max = t_max;
    }

    /// Lets the walk take at most `cells` more cells before it hands over.
    pub(super) fn limit_cells(&mut self, cells: usize) {
        self.cells_left = cells;
    }
}

/// Cells a near walk takes before handing over to a full cast.
const STRETCH_CELLS: usize = 64;

/// What a near walk found.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) enum Near {
    /// The walk found the hit, or the end of the range.
    Settled(Option<f64>),
    /// Nothing yet: cast properly from here.
    ContinueFrom(f64),
    /// The start is below the surface: the hit lies before it.
    HitBehindStart,
}

impl HeightPyramid {
    /// A clearance walk along the ray over `[t_min, t_max]`, or where exact marching starts
    /// at once (no clearance field, or a vertical ray).
    #[inline(always)]
    pub(super) fn clear_walk(
        &self,
        origin: [f64; 3],
        dir: [f64; 3],
        t_min: f64,
        t_max: f64,
    ) -> Result<ClearWalk, f64> {
        let Some(c) = &self.clearance else {
            return Err(t_min);
        };
        let cells_per_t = dir[0].abs().max(dir[1].abs()) / self.geometry.resolution_m;
        if cells_per_t < 1e-9 {
            return Err(t_min);
        }
        // Inverses up front: each step depends on the one before, so a division in it would
        // sit on the critical path.
        Ok(ClearWalk {
            origin,
            dir,
            cells_per_t,
            t_per_cell: 1.0 / cells_per_t,
            t_per_drop_m: if dir[2] < 0.0 {
                -1.0 / dir[2]
            } else {
                f64::INFINITY
            },
            inv_res: 1.0 / self.geometry.resolution_m,
            inv_dz: 1.0 / c.dz_m,
            layers_below: if dir[2] < 0.0 { 1.0 } else { 0.0 },
            t: t_min,
            t_max,
        })
    }

    /// One step of sphere tracing: as far as the clearance field proves empty at the ray's
    /// height, unless that is under two cells or the ray is off the grid.
    #[inline(always)]
    pub(super) fn clear_step(&self, c: &Clearance, w: &mut ClearWalk) -> ClearStep {
        let g = &self.geometry;
        let inv_res = w.inv_res;
        let t = w.t;
        let x = (w.origin[0] + w.dir[0] * t - g.origin.x_m) * inv_res;
        let y = (w.origin[1] + w.dir[1] * t - g.origin.y_m) * inv_res;
        if !(x >= 0.0 && y >= 0.0 && x < g.width as f64 && y < g.height as f64) {
            // Outside the grid: only the exact march knows whether it re-enters.
            return ClearStep::Exact(t);
        }
        let z = w.origin[2] + w.dir[2] * t;
        let layer = (z - c.z0_m) * w.inv_dz - w.layers_below;
        if layer < 0.0 {
            return ClearStep::Exact(t);
        }
        let k = (layer as usize).min(c.count - 1);
        let z_k = c.z0_m + k as f64 * c.dz_m;
        // d is the least distance of the point's block, so no more than the point's own cell's:
        // no cell reaching z_k lies within d - 1 king moves of it, and a point moved by at
        // most d - 1.5 cells along each axis stays in those cells.
        let (bx, by) = (x as usize / CLEAR_BLOCK, y as usize / CLEAR_BLOCK);
        let d = c.layers[k * c.layer_len + Level::tiled(c.tiles_w, bx, by)] as f64 - 1.5;
        let mut step = d * w.t_per_cell;
        // A ray that never falls has no drop limit (infinite t_per_drop_m; at z == z_k the
        // product is NaN, which the comparison leaves aside). Should rounding put z_k a hair
        // above z, the limit is -inf and the exact walk takes over.
        let drop_limit = (z - z_k) * w.t_per_drop_m;
        if drop_limit < step {
            step = drop_limit;
        }
        if step * w.cells_per_t < 2.0 {
            return ClearStep::Exact(t);
        }
        w.t = t + step;
        if w.t >= w.t_max {
            return ClearStep::Clear;
        }
        ClearStep::Open
    }

    /// [`cast`](Self::cast) for `N` rays, each from its origin, their clearance walks stepped
    /// in turn so their chains of dependent steps overlap.
    pub fn cast_side_by_side<const N: usize>(
        &self,
        origins: [[f64; 3]; N],
        dirs: [[f64; 3]; N],
        t_max_m: f64,
    ) -> [Option<f64>; N] {
        let Some(c) = &self.clearance else {
            return std::array::from_fn(|i| self.cast(origins[i], dirs[i], 0.0, t_max_m));
        };
        // Where each ray's exact walk starts; None once it is known to hit nothing.
        let mut exact_from: [Option<f64>; N] = [None; N];
        let mut walks: [Option<ClearWalk>; N] = [None; N];
        let mut walking = 0;
        for i in 0..N {
            match self.clear_walk(origins[i], dirs[i], 0.0, t_max_m) {
                Ok(w) => {
                    walks[i] = Some(w);
                    walking += 1;
                }
                Err(t) => exact_from[i] = Some(t),
            }
        }
        while walking > 0 {
            for i in 0..N {
                let Some(w) = walks[i].as_mut() else { continue };
                match self.clear_step(c, w) {
                    ClearStep::Open => continue,
                    ClearStep::Exact(t) => exact_from[i] = Some(t),
                    ClearStep::Clear => {}
                }
                walks[i] = None;
                walking -= 1;
            }
        }
        std::array::from_fn(|i| {
            exact_from[i].and_then(|t| self.cast_near(origins[i], dirs[i], t, t_max_m))
        })
    }

    /// A near walk from `t_start` (no clipping, no pyramid, almost no setup), or what it
    /// settles at once: off the grid, or starting below the surface.
    #[inline(always)]
    pub(super) fn near_walk(
        &self,
        origin: [f64; 3],
        dir: [f64; 3],
        t_start: f64,
        t_max: f64,
    ) -> Result<NearWalk, Near> {
        let g = &self.geometry;
        let inv_res = 1.0 / g.resolution_m;
        let ox = (origin[0] - g.origin.x_m) * inv_res;
        let oy = (origin[1] - g.origin.y_m) * inv_res;
        let (dx, dy, dz) = (dir[0] * inv_res, dir[1] * inv_res, dir[2]);
        let (px, py) = (ox + dx * t_start, oy + dy * t_start);
        if !(px >= 0.0 && py >= 0.0 && px < g.width as f64 && py < g.height as f64) {
            return Err(Near::ContinueFrom(t_start));
        }
        let (cx, cy) = (px as i64, py as i64);
        if origin[2] + dz * t_start <= self.levels[0].at(cx as usize, cy as usize) as f64 {
            return Err(Near::HitBehindStart);
        }
        let (step_x, step_y) = (step_sign(dx), step_sign(dy));
        let (inv_dx, inv_dy) = (1.0 / dx, 1.0 / dy);
        Ok(NearWalk {
            origin_z: origin[2],
            dz,
            cx,
            cy,
            step_x,
            step_y,
            tdx: inv_dx.abs(),
            tdy: inv_dy.abs(),
            tmx: exit_time(cx, 1.0, ox, inv_dx, step_x),
            tmy: exit_time(cy, 1.0, oy, inv_dy, step_y),
            t: t_start,
            t_max,
            cells_left: STRETCH_CELLS,
        })
    }

    /// The first hit of a ray a near walk has settled, or handed over with the way it ended:
    /// a full cast finishes it, from where the walk stopped or, if the walk started below the
    /// surface, from the origin.
    pub(super) fn finish(
        &self,
        origin: [f64; 3],
        dir: [f64; 3],
        near: Near,
        t_max_m: f64,
    ) -> Option<f64> {
        match near {
            Near::Settled(hit) => hit,
            Near::ContinueFrom(t) => self.cast(origin, dir, t, t_max_m),
            Near::HitBehindStart => self.cast(origin, dir, 0.0, t_max_m),
        }
    }

    /// Walks a near walk cell by cell until it settles or hands over. The axis each step
    /// crosses is picked by selects rather than a branch: along a diagonal ray it alternates
    /// unpredictably, and a mispredicted branch there cost more than the step itself.
    #[inline(always)]
    pub(super) fn near_run(&self, w: &mut NearWalk) -> Near {
        let level = &self.levels[0];
        let (width, height) = (self.geometry.width as u64, self.geometry.height as u64);
        let (oz, dz, t_max) = (w.origin_z, w.dz, w.t_max);
        let (step_x, step_y, tdx, tdy) = (w.step_x, w.step_y, w.tdx, w.tdy);
        let (mut cx, mut cy, mut tmx, mut tmy, mut t) = (w.cx, w.cy, w.tmx, w.tmy, w.t);
        let mut left = w.cells_left;
        let settled = loop {
            if left == 0 {
                break Near::ContinueFrom(t);
            }
            left -= 1;
            let top = level.at(cx as usize, cy as usize) as f64;
            let x_first = tmx < tmy;
            let t_cross = if x_first { tmx } else { tmy };
            let t_exit = if t_cross < t_max { t_cross } else { t_max };
            let z_in = oz + dz * t;
            let z_out = oz + dz * t_exit;
            let z_low = if z_in < z_out { z_in } else { z_out };
            if z_low <= top {
                // Into the column's side, or down onto its top.
                let hit = if z_in <= top {
                    t
                } else {
                    t + (top - z_in) / dz
                };
                break Near::Settled(Some(hit));
            }
            if t_exit >= t_max {
                break Near::Settled(None);
            }
            t = t_exit;
            // tdx is infinite only for a ray that never crosses in x, which then never
            // steps in x: the unpicked side adds nothing.
            cx += if x_first { step_x } else { 0 };
            cy += if x_first { 0 } else { step_y };
            tmx += if x_first { tdx } else { 0.0 };
            tmy += if x_first { 0.0 } else { tdy };
            // Negative cells wrap to huge values: one test per axis.
            if cx as u64 >= width || cy as u64 >= height {
                break Near::ContinueFrom(t);
            }
        };
        (w.cx, w.cy, w.tmx, w.tmy, w.t, w.cells_left) = (cx, cy, tmx, tmy, t, left);
        settled
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;
    use realms_core::Grid;

    /// The first hit of a ray walked exactly from `t_start`, before which it hits nothing,
    /// as the fan caster walks it.
    fn walk_from(
        p: &HeightPyramid,
        origin: [f64; 3],
        dir: [f64; 3],
        t_start: f64,
        t_max_m: f64,
    ) -> Option<f64> {
        let settled = match p.near_walk(origin, dir, t_start, t_max_m) {
            Ok(mut w) => p.near_run(&mut w),
            Err(n) => n,
        };
        p.finish(origin, dir, settled, t_max_m)
    }

    /// A 10 m square of 5 cm cells: a gently waved floor with 0.4 m rocks on about one cell
    /// in thirty, placed by `seed`.
    fn rocky_field(seed: u64) -> Grid<f32> {
        super::super::tests::field(200, 200, |x, y| {
            let v = ((y * 200 + x) as u64 * 7919 + seed * 104_729) % 89;
            if v < 3 {
                0.4
            } else {
                (x as f32 * 0.05).sin() * 0.05
            }
        })
    }

    proptest! {
        /// Four rays cast side by side, from origins a little apart (a sweeping lidar's
        /// beams as the rover moves), hit what each hits cast alone.
        #[test]
        fn rays_cast_side_by_side_hit_what_each_hits_alone(
            seed in 0u64..1000,
            ox in 1.0..9.0f64, oy in 1.0..9.0f64, oz in 0.1..0.6f64,
            yaw in 0.0..std::f64::consts::TAU, pitch in -0.3..0.1f64,
            spread in 0.0..0.2f64, drift in -0.01..0.01f64,
        ) {
            let p = HeightPyramid::new(&rocky_field(seed));
            let origins: [[f64; 3]; 4] =
                std::array::from_fn(|i| [ox + drift * i as f64, oy - drift * i as f64, oz]);
            let dirs: [[f64; 3]; 4] = std::array::from_fn(|i| {
                let (a, e) = (yaw + spread * i as f64, pitch + 0.02 * i as f64);
                [e.cos() * a.cos(), e.cos() * a.sin(), e.sin()]
            });
            let together = p.cast_side_by_side(origins, dirs, 12.0);
            for i in 0..4 {
                prop_assert_eq!(together[i], p.cast(origins[i], dirs[i], 0.0, 12.0), "ray {}", i);
            }
        }

        /// Walked from any start before its first hit (or anywhere in range, for a ray that
        /// hits nothing), a ray finds what a plain cast finds.
        #[test]
        fn a_walk_from_a_clear_start_hits_what_a_cast_hits(
            seed in 0u64..1000,
            ox in 1.0..9.0f64, oy in 1.0..9.0f64, oz in 0.1..0.6f64,
            yaw in 0.0..std::f64::consts::TAU, pitch in -0.5..0.1f64,
            start_share in 0.0..1.0f64,
        ) {
            let p = HeightPyramid::new(&rocky_field(seed));
            let o = [ox, oy, oz];
            let d = [pitch.cos() * yaw.cos(), pitch.cos() * yaw.sin(), pitch.sin()];
            let cast = p.cast(o, d, 0.0, 6.0);
            let start = cast.unwrap_or(6.0) * start_share;
            let walked = walk_from(&p, o, d, start, 6.0);
            match (walked, cast) {
                (Some(a), Some(b)) => prop_assert!((a - b).abs() < 1e-9, "{} against {}", a, b),
                (a, b) => prop_assert_eq!(a, b),
            }
        }
    }
}
