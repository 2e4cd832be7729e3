//! The HWMP airtime link metric of IEEE 802.11s (section 14.9): the channel time it costs to
//! deliver a test frame over a link, `c = (O + Bt / r) / (1 - e_f)`, with `O` the channel
//! access overhead, `Bt` the test frame's bits, `r` the link's rate and `e_f` its frame error
//! rate. A path's metric is the sum over its hops. A node switches to a new path only when
//! it is clearly better, as Linux's mesh code does, so routes do not flap between near-equal
//! paths.

use crate::radio::LinkQuality;

/// Channel access overhead for OFDM, microseconds.
pub const OVERHEAD_US: f64 = 75.0;
/// Test frame size, bits.
pub const TEST_FRAME_BITS: f64 = 8192.0;
/// A new path must cost at most this fraction of the current one to replace it.
pub const SWITCH_FRACTION: f64 = 0.9;

/// The airtime of one link, microseconds; infinite for a link that delivers nothing.
pub fn link_airtime_us(rate_mbps: f64, frame_error_rate: f64) -> f64 {
    if rate_mbps <= 0.0 || !(0.0..1.0).contains(&frame_error_rate) {
        return f64::INFINITY;
    }
    // Mb/s is bits per microsecond.
    (OVERHEAD_US + TEST_FRAME_BITS / rate_mbps) / (1.0 - frame_error_rate)
}

/// The airtime of a link as the radio model describes it.
pub fn airtime_of(link: &LinkQuality) -> f64 {
    link_airtime_us(link.phy_rate_mbps, link.per)
}

/// A path's metric: the sum over its hops.
pub fn path_airtime_us(hops: &[f64]) -> f64 {
    hops.iter().sum()
}

/// Whether a path costing `candidate_us` should replace the current one costing `current_us`.
pub fn should_switch(current_us: f64, candidate_us: f64) -> bool {
    candidate_us.is_finite()
        && (!current_us.is_finite() || candidate_us < SWITCH_FRACTION * current_us)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::radio::RadioConfig;

    #[test]
    fn the_metric_matches_the_standard_s_formula_by_hand() {
        // 6.5 Mb/s, no errors: 75 + 8192 / 6.5 = 1335.3 us.
        assert!((link_airtime_us(6.5, 0.0) - 1335.3077).abs() < 1e-3);
        // Half the frames lost doubles it.
        assert!((link_airtime_us(6.5, 0.5) - 2670.6154).abs() < 1e-3);
        assert!(link_airtime_us(0.0, 0.0).is_infinite());
        assert!(link_airtime_us(6.5, 1.0).is_infinite());
    }

    #[test]
    fn a_relay_halfway_beats_a_long_direct_link_on_airtime() {
        let r = RadioConfig::default();
        let direct = airtime_of(&r.link(220.0, 0.0));
        let relayed = path_airtime_us(&[
            airtime_of(&r.link(130.0, 0.0)),
            airtime_of(&r.link(100.0, 0.0)),
        ]);
        assert!(
            relayed < SWITCH_FRACTION * direct,
            "{relayed} against {direct}"
        );
        assert!(should_switch(direct, relayed));
        // Near-equal paths do not flap.
        assert!(!should_switch(1000.0, 950.0));
        assert!(should_switch(f64::INFINITY, 950.0));
        assert!(!should_switch(1000.0, f64::INFINITY));
    }
}
