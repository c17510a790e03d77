//! What a base driver computes: wheel powers from a commanded twist (the chair's kinematics,
//! thesis eqs. 4.5–4.6, inverted), and one laser scan made of the proximity cones.

use std::f64::consts::PI;

/// The wheel powers (fractions of `max_speed_mps`, in [−1, 1]) that drive at `v` m/s and
/// `omega` rad/s on wheels `track_m` apart. A twist beyond the chair's reach is scaled down
/// whole, so that the chair keeps the commanded curvature (as a real base driver's limiter
/// does) rather than one wheel saturating and the chair turning less than asked. Not finite
/// values are no motion.
pub fn powers(v: f64, omega: f64, max_speed_mps: f64, track_m: f64) -> [f64; 2] {
    if !(v.is_finite() && omega.is_finite() && max_speed_mps > 0.0) {
        return [0.0, 0.0];
    }
    let turn = omega * track_m / 2.0;
    let (left, right) = ((v - turn) / max_speed_mps, (v + turn) / max_speed_mps);
    let over = left.abs().max(right.abs()).max(1.0);
    [left / over, right / over]
}

/// One proximity sensor as the scan sees it, in the body frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Cone {
    /// Apex x, y metres (x ahead).
    pub at: [f64; 2],
    /// Axis, radians from the heading.
    pub axis_rad: f64,
    /// Full opening, radians.
    pub cone_rad: f64,
    /// Reach, metres: a reading at or beyond it is "nothing seen".
    pub range_m: f64,
}

/// A full turn of rays, `step_rad` apart, from −π.
#[derive(Debug, Clone, PartialEq)]
pub struct Scan {
    /// Radians between rays.
    pub step_rad: f64,
    /// Metres per ray: a reading, +∞ for free space a sensor saw to its reach, NaN where no
    /// sensor looks (REP 117).
    pub ranges: Vec<f32>,
    /// The farthest a ray can read, metres.
    pub range_max: f64,
}

/// The scan from the body's origin made of `cones` and their `readings` (metres). Each
/// reading is an arc across its cone (the cone reads the nearest thing anywhere in it, as a
/// sonar costmap layer draws it), each point of the arc binned by its bearing and distance
/// from the origin; the nearest point wins a ray.
pub fn scan(cones: &[Cone], readings: &[f64], step_rad: f64) -> Scan {
    let n = ((2.0 * PI / step_rad).round() as usize).max(1);
    let step = 2.0 * PI / n as f64;
    let mut ranges = vec![f32::NAN; n];
    let mut range_max: f64 = 0.0;
    for (c, &d) in cones.iter().zip(readings) {
        range_max = range_max.max(c.at[0].hypot(c.at[1]) + c.range_m);
        let seen = d.is_finite() && d < c.range_m;
        // Points across the cone at the scan's spacing, its axis always among them.
        let half = (c.cone_rad / 2.0 / step).floor() as i64;
        for k in -half..=half {
            let a = c.axis_rad + k as f64 * step;
            let reach = if seen { d.max(0.0) } else { c.range_m };
            let p = [c.at[0] + reach * a.cos(), c.at[1] + reach * a.sin()];
            let bearing = p[1].atan2(p[0]);
            let i = (((bearing + PI) / step).round() as usize) % n;
            let r = &mut ranges[i];
            if seen {
                let dist = p[0].hypot(p[1]) as f32;
                if r.is_nan() || r.is_infinite() || dist < *r {
                    *r = dist;
                }
            } else if r.is_nan() {
                *r = f32::INFINITY;
            }
        }
    }
    Scan { step_rad: step, ranges, range_max }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn powers_invert_the_chairs_kinematics() {
        let (max, track) = (0.49, 0.65);
        for (v, w) in [(0.3, 0.0), (0.2, 0.4), (-0.1, -0.3), (0.0, 1.0)] {
            let p = powers(v, w, max, track);
            let (v2, w2) = sim_model::velocity(max, track, p);
            assert!((v2 - v).abs() < 1e-12 && (w2 - w).abs() < 1e-12, "{v},{w} -> {p:?} -> {v2},{w2}");
        }
    }

    #[test]
    fn a_twist_beyond_reach_keeps_its_curvature() {
        let (max, track) = (0.49, 0.65);
        let p = powers(2.0, 2.0, max, track);
        assert!(p.iter().all(|x| x.abs() <= 1.0) && (p[1] - 1.0).abs() < 1e-12, "{p:?}");
        let (v, w) = sim_model::velocity(max, track, p);
        assert!((w / v - 1.0).abs() < 1e-12, "the radius of 1 m is kept: {v} {w}");
        assert_eq!(powers(f64::NAN, 0.0, max, track), [0.0, 0.0]);
        assert_eq!(powers(f64::INFINITY, 0.0, max, track), [0.0, 0.0]);
    }

    #[test]
    fn a_scan_puts_each_cone_where_its_reading_is() {
        let step = 1f64.to_radians();
        let cones = [
            Cone { at: [0.5, 0.0], axis_rad: 0.0, cone_rad: 2f64.to_radians(), range_m: 3.0 },
            Cone { at: [0.0, 0.3], axis_rad: PI / 2.0, cone_rad: 20f64.to_radians(), range_m: 3.0 },
        ];
        let s = scan(&cones, &[1.0, 5.0], step);
        assert_eq!(s.ranges.len(), 360);
        let ray = |deg: f64| s.ranges[((deg.to_radians() + PI) / s.step_rad).round() as usize];
        // Ahead: a wall 1 m from a sensor 0.5 m ahead of the origin is 1.5 m away.
        assert!((ray(0.0) - 1.5).abs() < 1e-6, "{}", ray(0.0));
        // Left: nothing within 3 m of the side sonar: free space, not a reading.
        assert_eq!(ray(90.0), f32::INFINITY);
        // Behind and between: no sensor looks there.
        assert!(ray(180.0 - 1.0).is_nan() && ray(45.0).is_nan());
        assert!((s.range_max - 3.5).abs() < 1e-12);
    }
}
