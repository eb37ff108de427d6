//! Power balance of a solution, per emission case and RGB channel.
//!
//! With B = E + ρ H and H = F B (radiosity and irradiance in power per area):
//! - emitted   Φ_E = Σ A_i E_i
//! - total     Σ A_i B_i (all power leaving surfaces)
//! - reflected Σ A_i (B_i − E_i) = Σ A_i ρ_i H_i
//! - incident  Σ A_i H_i (all power arriving at surfaces)
//! - absorbed  Σ A_i (1 − ρ_i) H_i
//! - escaped   total − incident: power that leaves through openings (0 in a closed
//!   scene, where rows sum to 1 and reciprocity gives Σ_i A_i F_ij = A_j).
//!
//! Conservation: emitted = absorbed + escaped, up to the residual. In a closed scene
//! with uniform ρ, total = Φ_E / (1 − ρ) (sum the geometric series of bounces).

use std::fmt;

use super::system::System;

/// Power balance of one emission case (index 0..3 = R, G, B).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct EnergyReport {
    pub emitted: [f64; 3],
    pub total: [f64; 3],
    pub reflected: [f64; 3],
    pub incident: [f64; 3],
    pub absorbed: [f64; 3],
    pub escaped: [f64; 3],
}

impl EnergyReport {
    /// (emitted − absorbed − escaped) / emitted per channel: 0 when power is conserved
    /// (0 for a channel that emits nothing).
    pub fn imbalance(&self) -> [f64; 3] {
        std::array::from_fn(|c| {
            if self.emitted[c] > 0.0 {
                (self.emitted[c] - self.absorbed[c] - self.escaped[c]) / self.emitted[c]
            } else {
                0.0
            }
        })
    }
}

/// The reports of all cases from B and H (`n × m`, see [`System`]).
pub(crate) fn energy_reports(sys: &System, b: &[f64], h: &[f64]) -> Vec<EnergyReport> {
    let m = sys.m;
    (0..sys.cases)
        .map(|k| {
            let mut r = EnergyReport::default();
            for i in 0..sys.n {
                let a = sys.area[i];
                for ch in 0..3 {
                    let c = i * m + 3 * k + ch;
                    r.emitted[ch] += a * sys.e[c];
                    r.total[ch] += a * b[c];
                    r.incident[ch] += a * h[c];
                    r.absorbed[ch] += a * (1.0 - sys.rho[i][ch]) * h[c];
                }
            }
            for ch in 0..3 {
                r.reflected[ch] = r.total[ch] - r.emitted[ch];
                r.escaped[ch] = r.total[ch] - r.incident[ch];
            }
            r
        })
        .collect()
}

/// Escaped power below this fraction of the total is more than rounding and row
/// accuracy explain (a closed scene's rows sum to 1 within about 1e-6 with `contour`).
const CREATED_LIGHT: f64 = 1e-3;

/// The first case and channel fraction where the escaped power is negative beyond
/// [`CREATED_LIGHT`] of the total: light created by rows that sum above 1.
pub(crate) fn created_light(reports: &[EnergyReport]) -> Option<(usize, f64)> {
    reports.iter().enumerate().find_map(|(k, r)| {
        (0..3)
            .filter(|&c| r.total[c] > 0.0)
            .map(|c| r.escaped[c] / r.total[c])
            .find(|&f| f < -CREATED_LIGHT)
            .map(|f| (k, f))
    })
}

fn rgb(v: &[f64; 3]) -> String {
    format!("{:.6e} {:.6e} {:.6e}", v[0], v[1], v[2])
}

impl fmt::Display for EnergyReport {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        writeln!(f, "  emitted    {}", rgb(&self.emitted))?;
        writeln!(f, "  total      {}", rgb(&self.total))?;
        writeln!(f, "  reflected  {}", rgb(&self.reflected))?;
        writeln!(f, "  incident   {}", rgb(&self.incident))?;
        writeln!(f, "  absorbed   {}", rgb(&self.absorbed))?;
        writeln!(f, "  escaped    {}", rgb(&self.escaped))?;
        let im = self.imbalance();
        write!(f, "  imbalance  {:.2e} {:.2e} {:.2e}", im[0], im[1], im[2])
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn created_light_is_a_negative_escape_beyond_rounding() {
        let report = |escaped: f64| EnergyReport {
            total: [2.0; 3],
            escaped: [0.0, escaped, 0.0],
            ..Default::default()
        };
        assert_eq!(created_light(&[report(-1e-8), report(0.5)]), None);
        assert_eq!(created_light(&[report(0.0), report(-0.4)]), Some((1, -0.2)));
    }
}
