//! Whether the robot stayed the same while it was recorded.
//!
//! A battery's charge falls from drive to drive, and with it the drive force; tyres warm up and
//! wear, and their grip changes. No effect of the library and no term of the search follows the
//! recording's time, so the diagnosis of such data names nothing, while the model's error is
//! several times what it is on data of a robot that stayed the same. The drift check takes each
//! physical quantity the identifiable nominal parameters make up (car: the drive force `C_m1`,
//! `C_m2`; the tyres' grip `D_f`, `D_r`; the rolling resistance `C_r0`; pushing: each free
//! parameter alone), scales its parameters together by `s` (the model's other parameters as they
//! are) and fits `s` on the fit half twice: once over the whole recording, and once on each of
//! [`DRIFT_BLOCKS`] blocks of it alone (by the share of the data recorded before a window). The
//! line through the blocks' scales (Theil–Sen),
//!
//! ```text
//! s(τ) = s̄ · (1 + β·(τ − ½))        τ ∈ [0, 1): the share of the data recorded before
//! ```
//!
//! is scored on the held-out half against the blocks' median scale, with the bootstrap over held-out
//! segments (and the second look of a candidate where its bound is not above 0), the Bonferroni
//! correction over the quantities tried and the bar of an effect
//! ([`DiagnoseConfig::min_reduction`]), and must rise or fall by more than two standard errors of
//! the blocks' scatter about it: a change along the recording, not a scatter from block to
//! block. `β` is the relative change from the recording's start to its end.
//! The segments of both halves come from all over the recording, so each half sees every block.

use super::*;

/// Blocks of the recording over which a drifting quantity is held constant: fine enough for a
/// linear drift (its steps are a sixth of the change), coarse enough that each block holds
/// windows of both halves.
pub const DRIFT_BLOCKS: usize = 6;

/// The range of a quantity's constant scale against the model's values.
const SCALE_RANGE: (f64, f64) = (0.2, 5.0);

/// A physical quantity of the nominal model that changes along the recording
/// ([`Diagnosis::drift`]).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Drift {
    /// The quantity (`the drive force`, …).
    pub quantity: String,
    /// What it changes (`vx`, `omega`, …, as effect files name them).
    pub targets: Vec<String>,
    /// Its nominal parameters, scaled together.
    pub params: Vec<String>,
    /// What changes it over a recording.
    pub causes: String,
    /// Its scale against the model's values, constant over the recording: the median of the
    /// blocks' scales.
    pub constant: f64,
    /// The line through the blocks' scales at the recording's start and end.
    pub start: f64,
    /// See `start`.
    pub end: f64,
    /// `β`: the relative change from start to end, `(end − start)/s̄`, of the line through
    /// the blocks' scales.
    pub change: f64,
    /// Its standard error from the blocks' scatter about the line (−1: not available).
    pub change_std: f64,
    /// The parameters' values at the recording's start and end (`name → [start, end]`).
    pub values: BTreeMap<String, [f64; 2]>,
    /// Held-out k-step error with the quantity's constant scale and along the line.
    pub error_before: f64,
    /// See `error_before`.
    pub error_after: f64,
    /// `1 − error_after/error_before`.
    pub error_reduction: f64,
    /// Lower end of its one-sided bootstrap interval (Bonferroni over the quantities tried).
    pub ci_lower: f64,
    /// Where the reduction is large enough but its bound is not above 0: the second look, the
    /// drift fitted on the held-out half and scored on the fit half, both pooled.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub cross_fit: Option<CrossFit>,
    /// The reduction is at least `min_reduction`, its bound (or the second look's) above 0, and
    /// the change more than two standard errors.
    pub significant: bool,
    /// Every quantity tried: the held-out error its drift removes.
    pub tried: BTreeMap<String, f64>,
    /// Other quantities whose drift is significant on what this one changes and removes less
    /// than [`DiagnoseConfig::min_reduction`] less: these data hardly tell them apart
    /// (`quantity → change`; a weaker drive and a larger rolling resistance both slow the car).
    #[serde(default, skip_serializing_if = "BTreeMap::is_empty")]
    pub alike: BTreeMap<String, f64>,
    /// The scale fitted alone on each block of the recording's fit half: `[τ at the block's
    /// centre, scale, cluster-robust σ]`.
    pub blocks: Vec<[f64; 3]>,
}

impl Drift {
    /// One line: the quantity's start, end and change, and the error its drift removes.
    pub fn text(&self) -> String {
        let sd = if self.change_std >= 0.0 {
            format!(" ± {:.0}", 100.0 * self.change_std)
        } else {
            String::new()
        };
        let values: Vec<String> = self
            .values
            .iter()
            .map(|(n, v)| format!("{n} {} → {}", g4(v[0]), g4(v[1])))
            .collect();
        let mut second = match &self.cross_fit {
            Some(x) => format!("; {}", cross_fit_text(x)),
            None => String::new(),
        };
        for (q, c) in &self.alike {
            second.push_str(&format!(
                "; {q} changing by {:+.0} % removes nearly as much: these data hardly tell the two apart",
                100.0 * c
            ));
        }
        format!(
            "{} ({}) over the recording: ×{:.3} → ×{:.3} of the model's ({:+.0}{sd} % from the first data to the last; constant ×{:.3}), {}; following it removes {:.1} % of the held-out error (bootstrap lower bound {:.1} %){second}",
            self.quantity,
            self.params.join(", "),
            self.start,
            self.end,
            100.0 * self.change,
            self.constant,
            values.join(", "),
            100.0 * self.error_reduction,
            100.0 * self.ci_lower,
        )
    }

    /// What every quantity's drift removes: `quantity x %, …`.
    pub fn tried_text(&self) -> String {
        let tried: Vec<String> = self
            .tried
            .iter()
            .map(|(n, r)| format!("{n} {:.1} %", 100.0 * r))
            .collect();
        tried.join(", ")
    }

    /// What the user can do about it.
    pub fn advice(&self) -> String {
        format!(
            "the robot changed while it was recorded ({}), and no fixed model follows it: identify {p} again before each run (`dynlab train --kind physics --free {p}` on a short drive recorded just before), or train on data recorded in the state the robot will run in",
            self.causes,
            p = self.params.join(",")
        )
    }
}

/// One look at a drift ([`Ctx::drift_look`]).
struct Look {
    /// The scale over the whole recording: the blocks' median.
    constant: f64,
    /// Per block: `[τ at its centre, scale, σ]` (blocks without fit windows left out).
    blocks: Vec<[f64; 3]>,
    /// The line through the blocks' scales: `[s̄, β]` and the σ of β (NaN: not available).
    line: [f64; 3],
    ws: Vec<Window>,
    before: Vec<f64>,
    after: Vec<f64>,
}

/// The share of the recording before the centre of block `b`.
fn centre(b: usize) -> f64 {
    (b as f64 + 0.5) / DRIFT_BLOCKS as f64
}

/// The median of `v` (NaN when empty).
fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    match v.len() {
        0 => f64::NAN,
        n if n % 2 == 1 => v[n / 2],
        n => 0.5 * (v[n / 2 - 1] + v[n / 2]),
    }
}

/// The Theil–Sen line through the points `[τ, s, …]`: the median of the pairwise slopes and
/// the median intercept at `τ = ½`, `[slope, s̄]` (one block of few windows fitted far off does
/// not tilt it).
fn theil_sen(points: &[[f64; 3]]) -> [f64; 2] {
    let n = points.len();
    let slopes: Vec<f64> = (0..n)
        .flat_map(|i| (i + 1..n).map(move |j| (i, j)))
        .filter(|&(i, j)| points[j][0] != points[i][0])
        .map(|(i, j)| (points[j][1] - points[i][1]) / (points[j][0] - points[i][0]))
        .collect();
    let slope = if slopes.is_empty() {
        0.0
    } else {
        median(slopes)
    };
    let mid = median(points.iter().map(|p| p[1] - slope * (p[0] - 0.5)).collect());
    [slope, mid]
}

/// The line `s̄·(1 + β·(τ − ½))` through the points `[τ, s, …]` by Theil–Sen: `[s̄, β, σ_β]`
/// (σ NaN with fewer than three points). σ is the larger of two estimates of the blocks'
/// scatter about the line: the residuals' median absolute deviation, and the jackknife over
/// the blocks (the line refitted without each in turn). The first alone collapses where three
/// of five blocks lie on the line through them, as Theil–Sen's lines often do: on a car whose
/// rolling resistance did not change, blocks at ×1.29, 1.15, 1.21, 1.43, 1.28 gave a rise of
/// 15 % ± 1.8 % (the jackknife: ± 8.5 %).
fn trend(points: &[[f64; 3]]) -> [f64; 3] {
    let n = points.len();
    let [slope, mid] = theil_sen(points);
    if n < 3 || !(mid.is_finite() && mid != 0.0) {
        return [mid, 0.0, f64::NAN];
    }
    let mad = median(
        points
            .iter()
            .map(|p| (p[1] - mid - slope * (p[0] - 0.5)).abs())
            .collect(),
    );
    let tm = points.iter().map(|p| p[0]).sum::<f64>() / n as f64;
    let sxx: f64 = points.iter().map(|p| (p[0] - tm).powi(2)).sum();
    let sd_mad = 1.4826 * mad / sxx.sqrt() * (n as f64 / (n as f64 - 2.0)).sqrt() / mid.abs();
    let betas: Vec<f64> = (0..n)
        .map(|i| {
            let rest: Vec<[f64; 3]> = [&points[..i], &points[i + 1..]].concat();
            let [s, m] = theil_sen(&rest);
            s / m
        })
        .collect();
    let avg = betas.iter().sum::<f64>() / n as f64;
    let jack =
        ((n - 1) as f64 / n as f64 * betas.iter().map(|b| (b - avg).powi(2)).sum::<f64>()).sqrt();
    // (`max` keeps the deviation's σ where a refit without a block has no line: NaN)
    [mid, slope / mid, sd_mad.max(jack)]
}

/// A physical quantity of the nominal model: its name, its parameters, what changes it over a
/// recording, and the state derivatives it changes.
struct Quantity {
    name: String,
    params: Vec<String>,
    causes: &'static str,
    targets: &'static [Target],
}

/// The physical quantities the nominal parameters `names` make up. A parameter of no quantity
/// is one alone.
fn quantities(world: World, names: &[String]) -> Vec<Quantity> {
    const BLOCK: &[Target] = &[
        Target::X,
        Target::Y,
        Target::Theta,
        Target::BlockX,
        Target::BlockY,
    ];
    let groups: &[(&str, &[&str], &str, &[Target])] = match world {
        World::Car => &[
            (
                "the drive force",
                &["Cm1", "Cm2"],
                "a battery's charge, the motor's temperature",
                &[Target::Vx],
            ),
            (
                "the tyres' grip",
                &["Df", "Dr"],
                "the tyres' temperature and wear, the floor",
                &[Target::Grip, Target::Vy, Target::Omega],
            ),
            (
                "the rolling resistance",
                &["Cr0"],
                "the bearings' and tyres' temperature",
                &[Target::Vx],
            ),
        ],
        World::Push => &[],
    };
    let mut out: Vec<Quantity> = groups
        .iter()
        .map(|(q, ps, causes, targets)| Quantity {
            name: q.to_string(),
            params: ps
                .iter()
                .filter(|p| names.iter().any(|n| n == *p))
                .map(|p| p.to_string())
                .collect(),
            causes,
            targets,
        })
        .filter(|q| !q.params.is_empty())
        .collect();
    for n in names {
        if !out.iter().any(|q| q.params.contains(n)) {
            out.push(match world {
                World::Car => Quantity {
                    name: n.clone(),
                    params: vec![n.clone()],
                    causes: "wear, temperature",
                    targets: &[Target::Vx, Target::Vy, Target::Omega],
                },
                World::Push => Quantity {
                    name: n.clone(),
                    params: vec![n.clone()],
                    causes: "the table's wear, dust, humidity",
                    targets: BLOCK,
                },
            });
        }
    }
    out
}

impl Ctx<'_> {
    /// The block of the recording a window lies in.
    fn block(&self, w: &Window) -> usize {
        let place = self.d.place.get(w.trajectory).copied().unwrap_or(0.0);
        ((place * DRIFT_BLOCKS as f64) as usize).min(DRIFT_BLOCKS - 1)
    }

    /// Per window of `ws`, the k-step error of `physics` with the parameters `idx` scaled by
    /// `scale(block)`, and (with `resid`) the residuals block by block (each block's rows
    /// step-major). `None` where a value is out of its parameter's range.
    fn drifting_errors(
        &self,
        physics: &PhysicsModel,
        idx: &[usize],
        scale: &dyn Fn(usize) -> f64,
        ws: &[Window],
        mut resid: Option<&mut Vec<f64>>,
    ) -> Option<Vec<f64>> {
        let mut err = vec![0.0; ws.len()];
        for b in 0..DRIFT_BLOCKS {
            let here: Vec<usize> = (0..ws.len()).filter(|&j| self.block(&ws[j]) == b).collect();
            if here.is_empty() {
                continue;
            }
            let mut p = physics.params().to_vec();
            for &i in idx {
                p[i] *= scale(b);
            }
            let mut m = physics.clone();
            m.set_params(&p).ok()?;
            let sub: Vec<Window> = here.iter().map(|&j| ws[j]).collect();
            let e = self.errors(m, &sub, resid.as_deref_mut());
            for (j, v) in here.into_iter().zip(e) {
                err[j] = v;
            }
        }
        Some(err)
    }

    /// Fits one scale of the parameters `idx` of `physics` on the windows `ws` of the fit half,
    /// from `start`: the scale and its cluster-robust σ.
    fn fit_scale(
        &self,
        physics: &PhysicsModel,
        idx: &[usize],
        start: f64,
        ws: &[Window],
    ) -> [f64; 2] {
        let (k, ds) = (self.d.k, self.d.ds);
        let resid_on = |th: &[f64], ws: &[Window], r: &mut Vec<f64>| {
            self.drifting_errors(physics, idx, &|_| th[0], ws, Some(r))
                .is_some()
        };
        let (lower, upper) = ([SCALE_RANGE.0], [SCALE_RANGE.1]);
        let step = |th: &[f64]| -> f64 {
            if th[0] + 1e-4 <= upper[0] {
                1e-4
            } else {
                -1e-4
            }
        };
        let fit_w = robust_windows(
            ws,
            ds,
            &[start],
            &|_| step(&[start]),
            &|th: &[f64], r: &mut Vec<f64>| resid_on(th, ws, r),
            SENSITIVITY_LIMIT,
            false,
        );
        let nr = ((fit_w.len() * k * ds) as f64).sqrt();
        let resid_of = |th: &[f64]| -> Vec<f64> {
            let mut r = Vec::new();
            match resid_on(th, &fit_w, &mut r) {
                true => r.iter().map(|x| x / nr).collect(),
                false => vec![f64::INFINITY],
            }
        };
        let step_of = |th: &[f64], _: usize| step(th);
        let mut fd = ForwardDifferences::new(&resid_of, &step_of);
        let mut eval = |th: &[f64], with_j: bool| fd.eval(th, with_j);
        let res = bounded_least_squares(
            &[start],
            &lower,
            &upper,
            &[true],
            self.cfg.iterations,
            &mut eval,
        );
        // clustered by segment, rows as `drifting_errors` gives them: block by block, then
        // (step, window, dimension)
        let (r, jac) = eval(&res.theta, true);
        let mut cluster = Vec::with_capacity(r.len());
        for b in 0..DRIFT_BLOCKS {
            let here: Vec<&Window> = fit_w.iter().filter(|w| self.block(w) == b).collect();
            for _ in 0..k {
                for w in &here {
                    cluster.extend(std::iter::repeat_n(w.trajectory, ds));
                }
            }
        }
        let sd = cluster_jackknife_std(&jac, &r, 1, &[true], &cluster)[0];
        [res.theta[0], if sd.is_finite() { sd } else { res.std[0] }]
    }

    /// The quantity's parameters `idx` of `physics` scaled by one scale and by one per block,
    /// fitted on this context's fit half; the one scale and the line through the blocks'
    /// scored on its held-out windows that `calm` keeps.
    fn drift_look(&self, physics: &PhysicsModel, idx: &[usize], calm: &[bool]) -> Option<Look> {
        let [constant, _] = self.fit_scale(physics, idx, 1.0, &self.fit_w);
        let blocks: Vec<[f64; 3]> = (0..DRIFT_BLOCKS)
            .filter_map(|b| {
                let ws: Vec<Window> = self
                    .fit_w
                    .iter()
                    .filter(|w| self.block(w) == b)
                    .copied()
                    .collect();
                (!ws.is_empty()).then(|| {
                    let [v, sd] = self.fit_scale(physics, idx, constant, &ws);
                    [centre(b), v, sd]
                })
            })
            .collect();
        let line = trend(&blocks);
        // the line is set against the blocks' own level, the median of their scales: the one
        // scale fitted over all the fit half keeps other windows (those a change of the scale
        // sends through a spin are left out by their share of the whole), and on a car with a
        // hidden drag it sat 6 % above every block's, which the line was credited with (20 %
        // of the held-out error, for a change of +4 %)
        let level = median(blocks.iter().map(|b| b[1]).collect());
        let level = if level.is_finite() { level } else { constant };
        let scored =
            |s: &dyn Fn(usize) -> f64| self.drifting_errors(physics, idx, s, &self.test_w, None);
        let along = |b: usize| line[0] * (1.0 + line[1] * (centre(b) - 0.5));
        let (before, after) = (scored(&|_| level)?, scored(&along)?);
        // windows the model spins through say nothing about a drift
        let mut look = Look {
            constant: level,
            line,
            blocks,
            ws: Vec::new(),
            before: Vec::new(),
            after: Vec::new(),
        };
        for (j, w) in self.test_w.iter().enumerate() {
            if calm.get(j).copied().unwrap_or(true) {
                look.ws.push(*w);
                look.before.push(before[j]);
                look.after.push(after[j]);
            }
        }
        Some(look)
    }

    /// The drift of the quantity `q` of `cur`'s physics, scored on the held-out half against
    /// its constant refit (`tested`: the quantities tried, for the Bonferroni correction). A
    /// drift large enough whose bound is not above 0 gets the second look of a candidate
    /// ([`CrossFit`]: fitted on the held-out half, scored on the fit half, both pooled).
    fn drift_of(&self, cur: &Current, q: &Quantity, tested: usize) -> Option<Drift> {
        let physics = &cur.physics;
        let params = &q.params;
        let idx: Vec<usize> = params
            .iter()
            .map(|n| physics.param_index(n))
            .collect::<Option<_>>()?;
        let look = self.drift_look(physics, &idx, &cur.calm)?;
        let (eb, ea) = (mean(&look.before), mean(&look.after));
        let raw = reduction(eb, ea);
        let alpha = 1.0 - self.cfg.confidence_for(tested);
        let seed =
            self.cfg.seed ^ 0x7A3D_91C4_E2B5_0F68 ^ (idx[0] as u64).wrapping_mul(0x9E37_79B9);
        let ci_lower = bootstrap_lower(
            &look.ws,
            &look.before,
            &look.after,
            self.cfg.bootstrap,
            alpha,
            seed,
        );
        let large = raw >= self.cfg.min_reduction && self.test_segments >= 2;
        let cross_fit = match large && ci_lower <= 0.0 && !self.swap[0].is_empty() {
            true => {
                let sw = self.swapped();
                let other = sw.drift_look(physics, &idx, &sw.calm(physics.clone()))?;
                let mut segments: Vec<usize> = look
                    .ws
                    .iter()
                    .chain(&other.ws)
                    .map(|w| w.trajectory)
                    .collect();
                segments.sort_unstable();
                segments.dedup();
                let ws = [look.ws.as_slice(), &other.ws].concat();
                let before = [look.before.as_slice(), &other.before].concat();
                let after = [look.after.as_slice(), &other.after].concat();
                Some(CrossFit {
                    other_reduction: reduction(mean(&other.before), mean(&other.after)),
                    reduction: reduction(mean(&before), mean(&after)),
                    ci_lower: bootstrap_lower(
                        &ws,
                        &before,
                        &after,
                        self.cfg.bootstrap,
                        0.5 * alpha,
                        seed ^ 0x6C62_272E_07BB_0142,
                    ),
                    segments: segments.len(),
                    params: BTreeMap::from([("change".to_string(), other.line[1])]),
                    folds: 2,
                })
            }
            false => None,
        };
        let [s, beta, sd] = look.line;
        let clear = sd.is_finite() && beta.abs() > 2.0 * sd;
        let significant = large
            && (ci_lower > 0.0
                || cross_fit
                    .as_ref()
                    .is_some_and(|c| c.counts(self.cfg.min_reduction)))
            && clear;
        let (start, end) = (s * (1.0 - 0.5 * beta), s * (1.0 + 0.5 * beta));
        Some(Drift {
            quantity: q.name.clone(),
            targets: q.targets.iter().map(|t| t.name().to_string()).collect(),
            params: params.clone(),
            causes: q.causes.to_string(),
            constant: look.constant,
            start,
            end,
            change: beta,
            change_std: if sd.is_finite() { sd } else { -1.0 },
            values: params
                .iter()
                .zip(&idx)
                .map(|(n, &i)| {
                    let v = physics.params()[i];
                    (n.clone(), [v * start, v * end])
                })
                .collect(),
            error_before: eb,
            error_after: ea,
            error_reduction: raw,
            ci_lower,
            cross_fit,
            significant,
            tried: BTreeMap::new(),
            alike: BTreeMap::new(),
            blocks: look.blocks,
        })
    }

    /// The drift check over the quantities the nominal parameters `names` of `cur`'s physics
    /// make up (on parallel threads): the drift that removes the most held-out error, with what
    /// every quantity's removes; `None` without a parameter to try or for a model other than a
    /// physics model.
    pub(super) fn drift(&self, cur: &Current, names: &[String]) -> Option<Drift> {
        if !self.pure_physics || names.is_empty() {
            return None;
        }
        let qs = quantities(self.model.world(), names);
        let tested = qs.len();
        let threads = std::thread::available_parallelism().map_or(1, |n| n.get());
        let mut found: Vec<Drift> = Vec::new();
        for chunk in qs.chunks(threads.max(1)) {
            let part: Vec<Option<Drift>> = std::thread::scope(|sc| {
                let hs: Vec<_> = chunk
                    .iter()
                    .map(|q| sc.spawn(move || self.drift_of(cur, q, tested)))
                    .collect();
                hs.into_iter().map(|h| h.join().ok().flatten()).collect()
            });
            found.extend(part.into_iter().flatten());
        }
        let tried: BTreeMap<String, f64> = found
            .iter()
            .map(|d| (d.quantity.clone(), d.error_reduction))
            .collect();
        found.sort_by(|a, b| {
            b.significant
                .cmp(&a.significant)
                .then(b.error_reduction.total_cmp(&a.error_reduction))
        });
        let mut found = found.into_iter();
        let mut best = found.next()?;
        best.tried = tried;
        best.alike = found
            .filter(|d| {
                best.significant
                    && d.significant
                    && d.error_reduction > best.error_reduction - self.cfg.min_reduction
                    && d.targets.iter().any(|t| best.targets.contains(t))
            })
            .map(|d| (d.quantity, d.change))
            .collect();
        Some(best)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Blocks with these scales, one per block from the first.
    fn blocks(scales: &[f64]) -> Vec<[f64; 3]> {
        scales
            .iter()
            .enumerate()
            .map(|(b, &s)| [centre(b), s, 0.01])
            .collect()
    }

    #[test]
    fn the_line_through_the_blocks_is_not_tilted_by_one_block_far_off() {
        // a staircase falling 30 % over the recording, one block fitted far off
        let pts = blocks(&[1.0, 0.9, 0.52, 0.8, 0.72, 0.7]);
        let [mid, beta, sd] = trend(&pts);
        assert!((mid - 0.85).abs() < 0.03, "{mid}");
        assert!((-0.5..-0.3).contains(&beta), "{beta}");
        assert!(sd > 0.0 && beta.abs() > 2.0 * sd, "{beta} ± {sd}");
        // a scatter without a trend: the change is within two standard errors
        let [_, beta, sd] = trend(&blocks(&[1.02, 0.97, 1.03, 0.98, 1.01, 0.99]));
        assert!(beta.abs() <= 2.0 * sd, "{beta} ± {sd}");
        // five blocks of a car whose rolling resistance did not change (the third sixth of
        // the recording without fit windows), three of them on one line: a rise of 15 % whose
        // blocks' median deviation from the line is 0.7 %, within the jackknife's two σ
        let pts = [
            [centre(0), 1.289, 0.109],
            [centre(1), 1.152, 0.007],
            [centre(3), 1.209, 0.145],
            [centre(4), 1.425, 0.003],
            [centre(5), 1.276, 0.063],
        ];
        let [_, beta, sd] = trend(&pts);
        assert!((0.1..0.2).contains(&beta), "{beta}");
        assert!(beta.abs() <= 2.0 * sd, "{beta} ± {sd}");
        // two blocks give a line but no standard error
        assert!(trend(&pts[..2])[2].is_nan());
        assert_eq!(median(vec![3.0, 1.0, 2.0, 10.0]), 2.5);
    }

    #[test]
    fn the_car_quantities_group_the_parameters_and_keep_the_rest_alone() {
        let names: Vec<String> = ["Df", "Dr", "Cm1", "Cm2", "Cr0", "Iz"]
            .iter()
            .map(|s| s.to_string())
            .collect();
        let qs = quantities(World::Car, &names);
        let got: Vec<(&str, Vec<&str>)> = qs
            .iter()
            .map(|q| {
                (
                    q.name.as_str(),
                    q.params.iter().map(|s| s.as_str()).collect(),
                )
            })
            .collect();
        assert_eq!(
            got,
            [
                ("the drive force", vec!["Cm1", "Cm2"]),
                ("the tyres' grip", vec!["Df", "Dr"]),
                ("the rolling resistance", vec!["Cr0"]),
                ("Iz", vec!["Iz"]),
            ]
        );
        // a quantity with none of its parameters identifiable is not tried
        let qs = quantities(World::Car, &["Cm1".to_string()]);
        assert_eq!(qs.len(), 1);
        assert_eq!(qs[0].params, ["Cm1"]);
    }
}
