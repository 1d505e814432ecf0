//! The finger's internal lattice (the metamaterial) as a linear-elastic truss:
//! layers of elliptical rings with a centre node, joined by ring beams, spokes,
//! longitudinal beams and diagonals. The base layer is clamped to the support.
//! The stiffness matrix is factorised once (dense Cholesky); each sample is then one
//! forward and one back substitution.

use super::SimError;
use super::contact::{Contact, FingerGeometry};

/// Parameters of the lattice.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LatticeParams {
    /// Layers from base to tip (the base layer is clamped), at least 2.
    pub layers: usize,
    /// Nodes on each ring, at least 3.
    pub ring_nodes: usize,
    /// Axial stiffness `E·A` of a beam, N (a beam of length L has stiffness E·A / L).
    pub beam_ea_n: f64,
    /// Diagonal stiffness added to every free degree of freedom, N/m (a weak tie to
    /// the rest shape; 0 leaves the truss alone).
    pub regularisation_n_per_m: f64,
    /// Include diagonal (shear) beams. Without them the truss is a mechanism and the
    /// solve only works with regularisation.
    pub diagonals: bool,
}

impl Default for LatticeParams {
    fn default() -> Self {
        Self {
            layers: 10,
            ring_nodes: 16,
            beam_ea_n: 7.0,
            regularisation_n_per_m: 5.0,
            diagonals: true,
        }
    }
}

/// Kind of beam, for drawing.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum BeamKind {
    Ring,
    Spoke,
    Longitudinal,
    Diagonal,
    /// The second diagonal of a cell (carries load, not drawn).
    CrossDiagonal,
}

/// A factorised lattice, ready to solve loads.
#[derive(Debug, Clone)]
pub(crate) struct Lattice {
    pub params: LatticeParams,
    /// Rest positions of all nodes, sensor frame, m. Layer-major: layer `k` holds
    /// nodes `k·(R+1) .. (k+1)·(R+1)`, the last of each layer being the centre.
    pub rest: Vec<[f64; 3]>,
    /// Beams as node index pairs, ordered far (tip) to near (base).
    pub beams: Vec<(usize, usize, BeamKind)>,
    /// Parametric angle of each ring node (NaN for centres).
    angle: Vec<f64>,
    /// Layer heights, m.
    pub heights: Vec<f64>,
    /// Lower Cholesky factor of the free-DOF stiffness.
    chol: Factor,
    /// Index of the first free node (the base layer is fixed).
    first_free: usize,
}

/// Deformed node positions.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Deformed {
    pub nodes: Vec<[f64; 3]>,
}

impl Lattice {
    pub(crate) fn new(finger: &FingerGeometry, params: LatticeParams) -> Result<Self, SimError> {
        finger.validate()?;
        let p = params;
        if p.layers < 2 || p.ring_nodes < 3 || p.layers * (p.ring_nodes + 1) > 2000 {
            return Err(SimError::InvalidParameter(format!(
                "lattice needs 2..  layers and 3.. ring nodes (at most 2000 nodes): {p:?}"
            )));
        }
        let ea_ok = p.beam_ea_n.is_finite() && p.beam_ea_n > 0.0;
        let reg_ok = p.regularisation_n_per_m.is_finite() && p.regularisation_n_per_m >= 0.0;
        if !(ea_ok && reg_ok) {
            return Err(SimError::InvalidParameter(format!(
                "lattice stiffness must be finite, beam_ea_n > 0, regularisation ≥ 0: {p:?}"
            )));
        }
        let r = p.ring_nodes;
        let per = r + 1;
        let mut rest = Vec::with_capacity(p.layers * per);
        let mut angle = Vec::with_capacity(p.layers * per);
        let mut heights = Vec::with_capacity(p.layers);
        for k in 0..p.layers {
            let h = finger.base_height_m + finger.length_m * k as f64 / (p.layers - 1) as f64;
            // Keep the tip layer just inside the finger.
            let h = h.min(finger.tip_height() - 1e-6);
            heights.push(h);
            let (a, b, _, _) = finger.semi_axes(h);
            for i in 0..r {
                let phi = std::f64::consts::TAU * i as f64 / r as f64;
                let (s, c) = phi.sin_cos();
                rest.push([a * c, b * s, h]);
                angle.push(phi);
            }
            rest.push([0.0, 0.0, h]);
            angle.push(f64::NAN);
        }
        let node = |k: usize, i: usize| k * per + (i % r);
        let centre = |k: usize| k * per + r;
        let mut beams = Vec::new();
        for k in (0..p.layers).rev() {
            for i in 0..r {
                beams.push((node(k, i), node(k, i + 1), BeamKind::Ring));
                beams.push((node(k, i), centre(k), BeamKind::Spoke));
                if k + 1 < p.layers {
                    beams.push((node(k, i), node(k + 1, i), BeamKind::Longitudinal));
                    if p.diagonals {
                        beams.push((node(k, i), node(k + 1, i + 1), BeamKind::Diagonal));
                        beams.push((node(k, i + 1), node(k + 1, i), BeamKind::CrossDiagonal));
                        beams.push((node(k, i), centre(k + 1), BeamKind::Spoke));
                    }
                }
            }
            if k + 1 < p.layers {
                beams.push((centre(k), centre(k + 1), BeamKind::Longitudinal));
            }
        }
        let first_free = per;
        let n = (rest.len() - first_free) * 3;
        let mut kmat = vec![0.0; n * n];
        for &(i, j, _) in &beams {
            let (a, b) = (rest[i], rest[j]);
            let d = [b[0] - a[0], b[1] - a[1], b[2] - a[2]];
            let len = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
            if len <= 0.0 {
                continue;
            }
            let k = p.beam_ea_n / len;
            let e = [d[0] / len, d[1] / len, d[2] / len];
            for (ni, si) in [(i, 1.0), (j, -1.0)] {
                for (nj, sj) in [(i, 1.0), (j, -1.0)] {
                    if ni < first_free || nj < first_free {
                        continue;
                    }
                    let (bi, bj) = ((ni - first_free) * 3, (nj - first_free) * 3);
                    for x in 0..3 {
                        for y in 0..3 {
                            kmat[(bi + x) * n + bj + y] += si * sj * k * e[x] * e[y];
                        }
                    }
                }
            }
        }
        for d in 0..n {
            kmat[d * n + d] += p.regularisation_n_per_m;
        }
        let chol = cholesky(&kmat, n)?;
        Ok(Self {
            params: p,
            rest,
            beams,
            angle,
            heights,
            chol,
            first_free,
        })
    }

    /// Nodal loads of a contact: each strip's force goes to the ring nodes around
    /// the contact's azimuth (Gaussian in angle) on the two layers around its height.
    fn loads(&self, finger: &FingerGeometry, contact: &Contact) -> Vec<f64> {
        let n = (self.rest.len() - self.first_free) * 3;
        let mut f = vec![0.0; n];
        let r = self.params.ring_nodes;
        let per = r + 1;
        let sigma = std::f64::consts::TAU / r as f64 * 0.8;
        let (s_az, c_az) = contact.azimuth.sin_cos();
        let spacing = self.heights[1] - self.heights[0];
        for strip in &contact.strips {
            if strip.force.iter().all(|v| *v == 0.0) {
                continue;
            }
            let (a, b, _, _) = finger.semi_axes(strip.h);
            // Parametric angle of the contact point on the ellipse.
            let psi = (a * s_az).atan2(b * c_az);
            let mut wa = [0.0; 64];
            let mut total = 0.0;
            let count = r.min(64);
            for (i, w) in wa.iter_mut().enumerate().take(count) {
                let phi = self.angle[i];
                let d = (phi - psi + std::f64::consts::PI).rem_euclid(std::f64::consts::TAU)
                    - std::f64::consts::PI;
                *w = (-(d / sigma).powi(2)).exp();
                total += *w;
            }
            if total <= 0.0 {
                continue;
            }
            let t = ((strip.h - self.heights[0]) / spacing).max(0.0);
            let k0 = (t.floor() as usize).min(self.params.layers - 2);
            let frac = (t - k0 as f64).clamp(0.0, 1.0);
            for (k, wk) in [(k0, 1.0 - frac), (k0 + 1, frac)] {
                if k == 0 || wk == 0.0 {
                    continue;
                }
                for (i, w) in wa.iter().enumerate().take(count) {
                    let node = k * per + i;
                    let base = (node - self.first_free) * 3;
                    let share = wk * w / total;
                    for x in 0..3 {
                        f[base + x] += share * strip.force[x];
                    }
                }
            }
        }
        f
    }

    /// Node positions under a contact's load.
    pub(crate) fn deform(
        &self,
        finger: &FingerGeometry,
        contact: &Contact,
    ) -> Result<Deformed, SimError> {
        let mut u = self.loads(finger, contact);
        solve(&self.chol, &mut u);
        if u.iter().any(|v| !v.is_finite()) {
            return Err(SimError::Solver(
                "lattice displacement is not finite".into(),
            ));
        }
        let mut nodes = self.rest.clone();
        for (i, node) in nodes.iter_mut().enumerate().skip(self.first_free) {
            let b = (i - self.first_free) * 3;
            node[0] += u[b];
            node[1] += u[b + 1];
            node[2] += u[b + 2];
        }
        Ok(Deformed { nodes })
    }
}

/// The largest condition number the lattice solve accepts. Every pivot `d` of the
/// Cholesky factorisation is at least the smallest eigenvalue of `K`, and the largest
/// diagonal entry at most the largest, so `max Kᵢᵢ / min d` is a lower bound of the
/// condition number; above this bound displacements would keep fewer than about six
/// of f64's sixteen significant digits, so the system is refused as near-singular.
pub(crate) const MAX_CONDITION: f64 = 1e10;

/// A lower Cholesky factor `L`, packed by rows (row i holds columns 0..=i), and
/// where each row's nonzeros start.
#[derive(Debug, Clone)]
struct Factor {
    l: Vec<f64>,
    /// Row i of `L` is exactly zero before column `row_start[i]`. A node couples only
    /// to its neighbours, and the zeros of a row of `K` before its first nonzero stay
    /// zero in `L` (no fill-in outside the envelope): the solve skips them, about
    /// four fifths of the factor for the finger's lattice.
    row_start: Vec<usize>,
}

/// Dense Cholesky `K = L Lᵀ`. Fails on a non-positive pivot (a singular lattice) or
/// one small enough that the condition number exceeds [`MAX_CONDITION`]
/// (near-singular) instead of producing garbage.
fn cholesky(k: &[f64], n: usize) -> Result<Factor, SimError> {
    let idx = |i: usize, j: usize| i * (i + 1) / 2 + j;
    let mut l = vec![0.0; n * (n + 1) / 2];
    let max_diag = (0..n).map(|i| k[i * n + i]).fold(0.0_f64, f64::max);
    if !(max_diag.is_finite() && max_diag > 0.0) {
        return Err(SimError::Solver(format!(
            "lattice stiffness has no positive finite diagonal (largest {max_diag:.3e})"
        )));
    }
    let tol = max_diag / MAX_CONDITION;
    for i in 0..n {
        for j in 0..=i {
            let mut s = k[i * n + j];
            let (ri, rj) = (idx(i, 0), idx(j, 0));
            for m in 0..j {
                s -= l[ri + m] * l[rj + m];
            }
            if i == j {
                if s.is_nan() || s <= tol || !s.is_finite() {
                    return Err(SimError::Solver(format!(
                        "lattice stiffness is singular or near-singular (pivot {s:.3e} at dof {i}: \
                         condition number above {:.1e}, the bound {MAX_CONDITION:.0e}): add \
                         diagonals or regularisation",
                        if s > 0.0 { max_diag / s } else { f64::INFINITY }
                    )));
                }
                l[idx(i, i)] = s.sqrt();
            } else {
                l[idx(i, j)] = s / l[idx(j, j)];
            }
        }
    }
    let row_start = (0..n)
        .map(|i| (0..i).find(|&j| l[idx(i, j)] != 0.0).unwrap_or(i))
        .collect();
    Ok(Factor { l, row_start })
}

/// Solve `L Lᵀ x = b` in place.
///
/// A contact loads the nodes around it, so `b` often starts with zeros: their
/// unknowns of `L y = b` are zero, and the forward pass starts at the first load.
/// Each row's leading zeros (see [`Factor::row_start`]) are skipped: terms that add
/// zero. The forward pass skips them in whole groups of eight, so that the terms left
/// fall into the same running sums of [`dot`]: the same bits as the whole rows.
fn solve(f: &Factor, b: &mut [f64]) {
    let (l, row_start) = (&f.l, &f.row_start);
    let n = b.len();
    let idx = |i: usize, j: usize| i * (i + 1) / 2 + j;
    let first = b.iter().position(|v| *v != 0.0).unwrap_or(n);
    b[..first].fill(0.0);
    for i in first..n {
        let start = first + (row_start[i].max(first) - first) / 8 * 8;
        let row = &l[idx(i, start)..idx(i, 0) + i];
        let s = dot(row, &b[start..i]);
        b[i] = (b[i] - s) / l[idx(i, i)];
    }
    for i in (0..n).rev() {
        let xi = b[i] / l[idx(i, i)];
        b[i] = xi;
        // Subtract column i of Lᵀ (row i of L) from the earlier unknowns.
        let start = row_start[i];
        let row = &l[idx(i, start)..idx(i, 0) + i];
        for (bj, a) in b[start..i].iter_mut().zip(row) {
            *bj -= a * xi;
        }
    }
}

/// `Σ aᵢ xᵢ` in eight running sums: the forward pass's sums are its critical path,
/// and one running sum waits on each addition (the lattice solve took a tenth of a
/// water grasp's frame that way).
fn dot(a: &[f64], x: &[f64]) -> f64 {
    let mut acc = [0.0f64; 8];
    let (a8, x8) = (a.chunks_exact(8), x.chunks_exact(8));
    let (a_rest, x_rest) = (a8.remainder(), x8.remainder());
    for (a, x) in a8.zip(x8) {
        for k in 0..8 {
            acc[k] += a[k] * x[k];
        }
    }
    let mut s = ((acc[0] + acc[4]) + (acc[1] + acc[5])) + ((acc[2] + acc[6]) + (acc[3] + acc[7]));
    for (a, x) in a_rest.iter().zip(x_rest) {
        s += a * x;
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `n` loads in ±1000, zero before `first` (a contact loads the nodes from some
    /// index on).
    fn loads_from(first: usize, n: usize, g: &mut impl rand::Rng) -> Vec<f64> {
        use rand::RngExt;
        (0..n)
            .map(|i| {
                if i < first {
                    0.0
                } else {
                    g.random_range(-1e3..1e3)
                }
            })
            .collect()
    }

    /// The solve against the plain one (one running sum, every row), on a random
    /// well-conditioned system with loads that start at every position, none, and
    /// all: the same solution to rounding.
    #[test]
    fn the_solve_matches_the_plain_solve_whatever_the_loads_leading_zeros() {
        use rand::{RngExt, SeedableRng};
        let n = 37;
        let mut g = rand_chacha::ChaCha8Rng::seed_from_u64(7);
        let m: Vec<f64> = (0..n * n).map(|_| g.random_range(-1.0..1.0)).collect();
        // K = M Mᵀ + n I: symmetric positive definite.
        let mut k = vec![0.0; n * n];
        for i in 0..n {
            for j in 0..n {
                k[i * n + j] = (0..n).map(|p| m[i * n + p] * m[j * n + p]).sum::<f64>()
                    + if i == j { n as f64 } else { 0.0 };
            }
        }
        let f = cholesky(&k, n).expect("spd");
        let l = &f.l;
        let plain = |b: &mut [f64]| {
            let idx = |i: usize, j: usize| i * (i + 1) / 2 + j;
            for i in 0..n {
                let s: f64 = (0..i).map(|m| l[idx(i, m)] * b[m]).sum();
                b[i] = (b[i] - s) / l[idx(i, i)];
            }
            for i in (0..n).rev() {
                b[i] /= l[idx(i, i)];
                for j in 0..i {
                    b[j] -= l[idx(i, j)] * b[i];
                }
            }
        };
        for first in [0, 1, 5, 8, 9, 20, 36, 37] {
            let b = loads_from(first, n, &mut g);
            let (mut fast, mut want) = (b.clone(), b.clone());
            solve(&f, &mut fast);
            plain(&mut want);
            for (i, (x, y)) in fast.iter().zip(&want).enumerate() {
                assert!(
                    (x - y).abs() <= 1e-12 * (1.0 + y.abs()),
                    "first load {first}, unknown {i}: {x} against {y}"
                );
            }
            // K x = b.
            for i in 0..n {
                let r: f64 = (0..n).map(|j| k[i * n + j] * fast[j]).sum::<f64>() - b[i];
                assert!(
                    r.abs() < 1e-8,
                    "first load {first}: residual {r} in row {i}"
                );
            }
        }
    }

    /// On a banded system (a lattice's shape: each unknown coupled to its near
    /// neighbours), skipping each row's leading zeros gives the whole rows' bits.
    #[test]
    fn the_solve_skipping_the_rows_leading_zeros_is_the_whole_rows_solve_bit_for_bit() {
        use rand::{RngExt, SeedableRng};
        let (n, band) = (90, 13);
        let mut g = rand_chacha::ChaCha8Rng::seed_from_u64(11);
        let mut k = vec![0.0; n * n];
        for i in 0..n {
            for j in i.saturating_sub(band)..i {
                let v = g.random_range(-1.0..1.0);
                k[i * n + j] = v;
                k[j * n + i] = v;
            }
            k[i * n + i] = 2.0 * band as f64;
        }
        let f = cholesky(&k, n).expect("spd");
        assert!(
            f.row_start
                .iter()
                .enumerate()
                .all(|(i, &s)| s == i.saturating_sub(band))
        );
        // The solve as it was before it skipped anything.
        let whole_rows = |b: &mut [f64]| {
            let idx = |i: usize, j: usize| i * (i + 1) / 2 + j;
            let first = b.iter().position(|v| *v != 0.0).unwrap_or(n);
            b[..first].fill(0.0);
            for i in first..n {
                let s = dot(&f.l[idx(i, first)..idx(i, 0) + i], &b[first..i]);
                b[i] = (b[i] - s) / f.l[idx(i, i)];
            }
            for i in (0..n).rev() {
                let xi = b[i] / f.l[idx(i, i)];
                b[i] = xi;
                for (bj, a) in b[..i].iter_mut().zip(&f.l[idx(i, 0)..idx(i, 0) + i]) {
                    *bj -= a * xi;
                }
            }
        };
        for first in [0, 1, 7, 8, 13, 14, 21, 40, 89, 90] {
            let b = loads_from(first, n, &mut g);
            let (mut fast, mut want) = (b.clone(), b.clone());
            solve(&f, &mut fast);
            whole_rows(&mut want);
            for (i, (x, y)) in fast.iter().zip(&want).enumerate() {
                // Bit for bit (a zero may differ only in its sign).
                assert!(
                    x.to_bits() == y.to_bits() || x.abs().max(y.abs()) < f64::MIN_POSITIVE,
                    "first load {first}, unknown {i}: {x} against {y}"
                );
            }
        }
    }

    #[test]
    fn the_dot_product_handles_every_length_and_extremes() {
        for len in [0, 1, 7, 8, 9, 16, 17] {
            let a: Vec<f64> = (0..len).map(|i| i as f64 + 1.0).collect();
            let want: f64 = a.iter().map(|v| v * v).sum();
            assert!(
                (dot(&a, &a) - want).abs() <= 1e-12 * want.max(1.0),
                "length {len}"
            );
        }
        assert!(dot(&[f64::MAX, 1.0], &[2.0, 1.0]).is_infinite());
        assert!(dot(&[f64::NAN], &[1.0]).is_nan());
    }

    #[test]
    fn cholesky_solves_a_small_system() {
        let k = [4.0, 2.0, 2.0, 3.0];
        let l = cholesky(&k, 2).expect("spd");
        let mut b = [2.0, 1.0];
        solve(&l, &mut b);
        assert!((4.0 * b[0] + 2.0 * b[1] - 2.0).abs() < 1e-12);
        assert!((2.0 * b[0] + 3.0 * b[1] - 1.0).abs() < 1e-12);
    }

    #[test]
    fn a_singular_matrix_is_a_clear_error() {
        let k = [1.0, 1.0, 1.0, 1.0];
        let err = cholesky(&k, 2).expect_err("singular");
        assert!(err.to_string().contains("singular"), "{err}");
    }

    /// Pivots just inside the documented bound are solved; just beyond, refused with
    /// the bound in the message, whether the small pivot is on the diagonal or
    /// appears only in the factorisation.
    #[test]
    fn near_singular_systems_beyond_the_bound_are_refused() {
        for eps in [1e-9, 1e-11] {
            let inside = 1.0 / eps < MAX_CONDITION;
            for k in [[1.0, 0.0, 0.0, eps], [1.0, 1.0, 1.0, 1.0 + eps]] {
                match cholesky(&k, 2) {
                    Ok(l) => {
                        assert!(inside, "{k:?} accepted");
                        let mut b = [1.0, 2.0];
                        solve(&l, &mut b);
                        let r0 = k[0] * b[0] + k[1] * b[1] - 1.0;
                        let r1 = k[2] * b[0] + k[3] * b[1] - 2.0;
                        assert!(r0.abs() < 1e-5 && r1.abs() < 1e-5, "{k:?}: {b:?}");
                    }
                    Err(e) => {
                        assert!(!inside, "{k:?} refused: {e}");
                        let m = e.to_string();
                        assert!(m.contains("near-singular") && m.contains("1e10"), "{m}");
                    }
                }
            }
        }
        assert!(cholesky(&[f64::NAN], 1).is_err());
        assert!(cholesky(&[0.0], 1).is_err());
    }
}
