//! Receding-horizon racing: re-solve from the measured state every control cycle.

use std::time::Duration;

use dynlab_sim::Track;

use super::cost::{InputLimits, Objective, Regulariser, TrackTerms};
use super::gd::{GdSettings, solve_gd_until};
use super::plant::{CarDynamics, Input, Plant, State};
use super::profile::SpeedProfile;
use super::sqp::{SqpSettings, solve_sqp_until};
use super::{Deadline, Problem, RacingError, Solution, SolveStatus};

/// Which optimiser the racer runs.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Optimizer {
    /// Trust-region SQP on Clarabel, track borders as hard constraints.
    Sqp,
    /// The paper's batch gradient descent with the excursion cost.
    Gd,
}

impl std::str::FromStr for Optimizer {
    type Err = RacingError;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s {
            "sqp" => Ok(Self::Sqp),
            "gd" => Ok(Self::Gd),
            other => Err(RacingError::setting("optimizer", other, "use sqp or gd")),
        }
    }
}

/// Settings of the racer. Defaults: the paper's n = 20 at 20 Hz.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default)]
pub struct RacerSettings {
    /// Control steps n in the horizon. Default 20.
    pub horizon: usize,
    /// Model steps per control step (control period = `hold · dt`; 5 × 10 ms = 20 Hz).
    /// Default 5.
    pub hold: usize,
    /// Optimiser. Default SQP.
    pub optimizer: Optimizer,
    /// Reward per metre of progress of `x_n` (linear; 0: off). Default 0.
    pub progress_weight: f64,
    /// Reference speed along the centre line \[m/s\] (the paper's "predefined high velocity").
    /// Default 2 (faster reference speeds spin the ORCA car in the default track's bends).
    pub reference_speed: f64,
    /// Lateral acceleration the reference speed allows in bends \[m/s²\]: the reference speed
    /// at arc length s is `min(reference_speed, √(a / |κ(s)|))` (`inf`: constant). Default
    /// `inf` (the default track's bends are driven at the reference speed; for tracks with
    /// hairpins set it, e.g. 5 with `braking = 3`, `acceleration = 1.5`).
    pub lateral_acceleration: f64,
    /// Deceleration the reference speed profile allows before bends \[m/s²\] (`inf`: none).
    /// Default `inf`.
    pub braking: f64,
    /// Acceleration the reference speed profile allows out of bends \[m/s²\] (`inf`: none;
    /// gentle: full throttle in a bend spins the car). Default `inf`.
    pub acceleration: f64,
    /// Arc length over which the centre line's curvature is averaged (either side) for the
    /// reference speed \[m\] (the driven line is wider than the centre line). Default 0.15.
    pub curvature_smoothing: f64,
    /// Weight of the reference-progress term per step (0: off). Default 1.
    pub reference_weight: f64,
    /// Start the reference progress from the car's current speed (at most `v₀ + a·t` with the
    /// profile's `acceleration`; see [`SpeedProfile::progress_from_speed`]) rather than at the
    /// profile's speed. Default false (no effect with an unlimited acceleration; on the ORCA track
    /// it slowed the true-model racer by ≈ 1.5 s per lap).
    pub reference_from_speed: bool,
    /// Weight of the body-frame lateral velocity `v_y²` per step (0: off): plans that slide
    /// cost more. Default 0.
    pub slip_weight: f64,
    /// Distance kept from the borders \[m\]. Default 0.03 (about half the car's width).
    pub margin: f64,
    /// Growth of the margin with the time ahead in the plan \[m/s\]: the plan's state `t`
    /// seconds ahead keeps `margin + margin_growth · t` from the borders (the model's position
    /// error grows with the prediction horizon; near steps, which the next cycles re-plan
    /// from measured states, keep the plain margin). Default 0 (constant margin).
    pub margin_growth: f64,
    /// Excursion cost weight. Default 1000.
    pub excursion_weight: f64,
    /// Input limits.
    pub limits: InputLimits,
    /// Regulariser.
    pub reg: Regulariser,
    /// SQP settings per cycle (few iterations: the warm start is close). Default 3 iterations
    /// with the fast QPs of [`SqpSettings::fast_qp`] (an `[sqp]` table in a settings TOML
    /// starts from [`SqpSettings::default`], Clarabel's defaults: the previous path, `iterations`
    /// 50 unless given).
    pub sqp: SqpSettings,
    /// GD settings per cycle. Default 5 iterations.
    pub gd: GdSettings,
    /// Initial guess on the first cycle: `[δ, d]` held. Default `[0, 0.5]`.
    pub initial: Input,
    /// Recovery: when the previous plan reached less than this fraction of the reference
    /// progress (the car stalled, e.g. after a spin, facing a border), the cycle also solves
    /// from full-lock left, straight and full-lock right starts at `recovery_throttle` and keeps
    /// the cheapest plan (0: off). From standstill the linearisation sees no effect of the
    /// steering, so the warm start alone stays stuck. Default 0.5.
    pub recovery_fraction: f64,
    /// Throttle of the recovery starts. Default 0.4.
    pub recovery_throttle: f64,
    /// Threads for a stalled cycle's solves (the warm start and the recovery starts): 1 solves
    /// them one after the other; 2 (or more) splits them over two threads (the warm start and the
    /// straight start on the calling thread, the full-lock starts on a second one). The plan
    /// does not depend on it (each solve is the same; the cheapest wins, ties to the earlier
    /// start) unless a `solve_budget` cuts solves short. Default 2.
    pub recovery_threads: usize,
    /// Wall-clock budget of one cycle's solve \[s\] (`inf`: none). When it runs out the
    /// optimiser starts no further iteration (an iteration is started only if the time left
    /// exceeds the longest one so far), recovery starts not yet begun are skipped, and the
    /// cheapest plan found is used. In a stalled cycle each thread shares the time left equally
    /// among the starts it still has to solve (a warm start stuck facing a border does not take
    /// the whole budget from the recovery starts) ([`RaceStep::deadline`] reports it; status
    /// [`SolveStatus::Deadline`]). The cycle can overrun it by at most one iteration that took
    /// longer than all before it. After three consecutive stalled cycles the next ones are
    /// solved in full, without the budget, until the car is moving again (a car held standing
    /// by short recovery solves is worse than a late command). Default `inf` (the laps of `dynlab eval race` are timed by
    /// the simulation, not the wall clock; the `racer` node sets its own budget).
    pub solve_budget: f64,
}

impl Default for RacerSettings {
    fn default() -> Self {
        Self {
            horizon: 20,
            hold: 5,
            optimizer: Optimizer::Sqp,
            progress_weight: 0.0,
            reference_speed: 2.0,
            lateral_acceleration: f64::INFINITY,
            braking: f64::INFINITY,
            acceleration: f64::INFINITY,
            curvature_smoothing: 0.15,
            reference_weight: 1.0,
            reference_from_speed: false,
            slip_weight: 0.0,
            margin: 0.03,
            margin_growth: 0.0,
            excursion_weight: 1000.0,
            limits: InputLimits::default(),
            reg: Regulariser {
                magnitude: [0.0, 0.0],
                rate: [0.05, 0.01],
                barrier: 1000.0,
            },
            sqp: SqpSettings {
                iterations: 3,
                ..SqpSettings::default()
            }
            .fast_qp(),
            gd: GdSettings {
                iterations: 5,
                ..GdSettings::default()
            },
            initial: [0.0, 0.5],
            recovery_fraction: 0.5,
            recovery_throttle: 0.4,
            recovery_threads: 2,
            solve_budget: f64::INFINITY,
        }
    }
}

/// One control cycle's result.
#[derive(Debug, Clone, PartialEq)]
pub struct RaceStep {
    /// The input to apply now.
    pub input: Input,
    /// How the solve ended.
    pub status: SolveStatus,
    /// Optimiser iterations.
    pub iterations: usize,
    /// Cost reached.
    pub cost: f64,
    /// Predicted states over the horizon (`x₀ … x_n`).
    pub predicted: Vec<State>,
    /// QPs that needed the elastic fallback.
    pub elastic_qps: usize,
    /// Whether a recovery start gave the plan (see [`RacerSettings::recovery_fraction`]).
    pub recovered: bool,
    /// Recovery starts solved this cycle (0 unless the racer had stalled; fewer than 3 when
    /// the `solve_budget` ran out before they began).
    pub recovery_solves: usize,
    /// Whether a solve of this cycle stopped at the `solve_budget` or a recovery start was
    /// skipped for it (see [`RacerSettings::solve_budget`]).
    pub deadline: bool,
}

/// Receding-horizon racer over a car model on a track.
#[derive(Debug, Clone)]
pub struct Racer<'a> {
    plant: Plant<'a>,
    track: &'a Track,
    settings: RacerSettings,
    warm: Vec<Input>,
    last: Option<Input>,
    segment: Option<usize>,
    profile: SpeedProfile,
    stalled: bool,
    /// Consecutive cycles that ended stalled.
    stalled_cycles: usize,
    /// Effect states of the model (`d_f`, `delta_w`) after the inputs this racer applied:
    /// its own command history, advanced by every applied input over the control period.
    extra: Option<Vec<f64>>,
}

impl<'a> Racer<'a> {
    /// A racer; checks the settings.
    pub fn new(
        model: &'a dyn CarDynamics,
        track: &'a Track,
        settings: RacerSettings,
    ) -> Result<Self, RacingError> {
        if settings.horizon == 0 {
            return Err(RacingError::setting(
                "horizon",
                settings.horizon,
                "need at least one control step",
            ));
        }
        if !(settings.margin >= 0.0 && settings.progress_weight.is_finite()) {
            return Err(RacingError::setting(
                "margin",
                settings.margin,
                "margin must be ≥ 0 and progress_weight finite",
            ));
        }
        for (key, value, fix) in [
            (
                "margin_growth",
                settings.margin_growth,
                "a growth of the margin in m per second of horizon, finite and ≥ 0 (0: constant)",
            ),
            (
                "slip_weight",
                settings.slip_weight,
                "a weight on v_y² must be finite and ≥ 0 (0: off)",
            ),
        ] {
            if !(value >= 0.0 && value.is_finite()) {
                return Err(RacingError::setting(key, value, fix));
            }
        }
        if !(0.0..=1.0).contains(&settings.recovery_fraction) {
            return Err(RacingError::setting(
                "recovery_fraction",
                settings.recovery_fraction,
                "a fraction of the reference progress in [0, 1] (0: no recovery starts)",
            ));
        }
        if settings.recovery_threads == 0 {
            return Err(RacingError::setting(
                "recovery_threads",
                settings.recovery_threads,
                "1 (solve the recovery starts one after the other) or more",
            ));
        }
        if settings.solve_budget.is_nan() || settings.solve_budget <= 0.0 {
            return Err(RacingError::setting(
                "solve_budget",
                settings.solve_budget,
                "a wall-clock budget per cycle in seconds, > 0 (inf: none)",
            ));
        }
        if !settings.recovery_throttle.is_finite() {
            return Err(RacingError::setting(
                "recovery_throttle",
                settings.recovery_throttle,
                "a finite throttle (clamped to the input limits)",
            ));
        }
        let plant = Plant::new(model, settings.hold)?;
        let profile = SpeedProfile::new(
            track,
            settings.reference_speed,
            settings.lateral_acceleration,
            settings.braking,
            settings.acceleration,
            settings.curvature_smoothing,
        )?;
        Ok(Self {
            profile,
            plant,
            track,
            warm: vec![settings.limits.clamp(settings.initial); settings.horizon],
            settings,
            last: None,
            segment: None,
            stalled: false,
            stalled_cycles: 0,
            extra: None,
        })
    }

    /// The reference speed profile along the track.
    pub fn profile(&self) -> &SpeedProfile {
        &self.profile
    }

    /// Control period \[s\].
    pub fn period(&self) -> f64 {
        self.plant.dt()
    }

    /// The settings.
    pub fn settings(&self) -> &RacerSettings {
        &self.settings
    }

    /// Forgets the warm start.
    pub fn reset(&mut self) {
        self.warm = vec![self.settings.limits.clamp(self.settings.initial); self.settings.horizon];
        self.last = None;
        self.segment = None;
        self.stalled = false;
        self.stalled_cycles = 0;
        self.extra = None;
    }

    /// The model's effect states at the next step (`d_f`, `delta_w`; empty without them): from
    /// the inputs this racer applied, settled at the warm start's first input before the first
    /// step.
    pub fn extra_states(&self) -> Vec<f64> {
        match &self.extra {
            Some(e) => e.clone(),
            None => self.plant.model().settled_extra(&self.warm[0]),
        }
    }

    /// One control cycle from the measured state `s`: solve from the shifted previous solution
    /// and return the first input. A failed solve returns the warm start's first input with its
    /// status.
    pub fn step(&mut self, s: State) -> Result<RaceStep, RacingError> {
        let st = &self.settings;
        let deadline = st
            .solve_budget
            .is_finite()
            .then(|| Deadline::after(Duration::from_secs_f64(st.solve_budget)));
        let here = match self.segment {
            Some(h) => self.track.locate_near([s[0], s[1]], h, 12),
            None => self.track.locate([s[0], s[1]]),
        };
        let v0 = if st.reference_from_speed {
            s[3].hypot(s[4])
        } else {
            f64::INFINITY
        };
        let reference = self
            .profile
            .progress_from_speed(here.arc, v0, self.plant.dt(), st.horizon);
        // the model's effect states from the racer's own command history
        let extra = self.extra_states();
        let problem = Problem {
            plant: self.plant.with_extra(&extra)?,
            s0: s,
            objective: Objective {
                targets: Vec::new(),
                track: Some(TrackTerms {
                    track: self.track,
                    progress_weight: st.progress_weight,
                    margin: st.margin,
                    margin_growth: st.margin_growth * self.plant.dt(),
                    excursion_weight: st.excursion_weight,
                    reference_weight: st.reference_weight,
                    reference_step: st.reference_speed * self.plant.dt(),
                    reference_progress: &reference,
                    slip_weight: st.slip_weight,
                }),
                limits: st.limits,
                reg: st.reg,
                u_prev: self.last,
                start_segment: Some(here.segment),
            },
        };
        // a car stuck for several cycles gets its recovery solved in full: its recovery starts
        // cut short by the budget need not beat a warm start that keeps it standing
        let deadline = deadline
            .as_ref()
            .filter(|_| self.stalled_cycles < STALLED_CYCLES_WITH_BUDGET);
        let solve = |start: &[Input], deadline: Option<&Deadline>| match st.optimizer {
            Optimizer::Sqp => solve_sqp_until(&problem, start, &st.sqp, deadline),
            Optimizer::Gd => solve_gd_until(&problem, start, &st.gd, deadline),
        };
        let mut starts = vec![self.warm.clone()];
        if self.stalled {
            let d = st.recovery_throttle;
            for delta in [-st.limits.steering_max, 0.0, st.limits.steering_max] {
                starts.push(vec![st.limits.clamp([delta, d]); st.horizon]);
            }
        }
        let mut solved = solve_starts(&starts, st.recovery_threads, deadline, &solve)?.into_iter();
        let mut sol = solved
            .next()
            .flatten()
            .expect("the warm start is always solved");
        let mut recovered = false;
        let mut recovery_solves = 0;
        let mut deadline_hit = sol.status == SolveStatus::Deadline;
        for alt in solved {
            let Some(alt) = alt else {
                deadline_hit = true;
                continue;
            };
            recovery_solves += 1;
            deadline_hit |= alt.status == SolveStatus::Deadline;
            if alt.cost < sol.cost {
                sol = alt;
                recovered = true;
            }
        }
        let goal = reference.last().copied().unwrap_or(0.0);
        self.stalled = st.recovery_fraction > 0.0
            && goal > 0.0
            && problem.objective.progress(&sol.states) < st.recovery_fraction * goal;
        self.stalled_cycles = if self.stalled {
            self.stalled_cycles + 1
        } else {
            0
        };
        let input = st.limits.clamp(sol.inputs[0]);
        // shift: drop the applied input, repeat the last
        let mut warm = sol.inputs[1..].to_vec();
        warm.push(*sol.inputs.last().unwrap_or(&input));
        self.warm = warm;
        self.last = Some(input);
        self.segment = Some(here.segment);
        if !extra.is_empty() {
            // the applied input is held for the control period: hold model steps
            let mut e = extra;
            for _ in 0..self.plant.hold() {
                self.plant.model().advance_extra(&mut e, &input);
            }
            self.extra = Some(e);
        }
        Ok(RaceStep {
            input,
            status: sol.status,
            iterations: sol.iterations,
            cost: sol.cost,
            predicted: sol.states,
            elastic_qps: sol.elastic_qps,
            recovered,
            recovery_solves,
            deadline: deadline_hit,
        })
    }
}

/// Consecutive stalled cycles solved within the `solve_budget`; the next ones solve the warm and
/// recovery starts in full (measured over DDS: a learned car that braked to a stop with the
/// budget cutting its recovery starts short stood for the rest of the run, throttle 0.12).
const STALLED_CYCLES_WITH_BUDGET: usize = 3;

/// Solves every start (the first is the warm start, the others recovery starts) on up to
/// `threads` threads. With a `deadline`, each thread shares the time left among the starts it
/// has left ([`Deadline::share`]: a stalled cycle's recovery starts get their turn instead of the
/// warm start using the whole budget), and a recovery start whose first iteration no longer
/// fits is skipped (`None`). Results in the order of `starts`; the first error in that order is
/// returned.
fn solve_starts<F>(
    starts: &[Vec<Input>],
    threads: usize,
    deadline: Option<&Deadline>,
    solve: &F,
) -> Result<Vec<Option<Solution>>, RacingError>
where
    F: Fn(&[Input], Option<&Deadline>) -> Result<Solution, RacingError> + Sync,
{
    // start i, with `left` starts (itself included) still to solve on this thread
    let run = |i: usize, left: usize| -> Option<Result<Solution, RacingError>> {
        let Some(d) = deadline else {
            return Some(solve(&starts[i], None));
        };
        if i > 0 && !d.allows_iteration() {
            return None;
        }
        let share = d.share(left);
        let out = solve(&starts[i], Some(&share));
        d.record(share.longest_iteration());
        Some(out)
    };
    let on_thread = |ids: Vec<usize>| -> Vec<(usize, Option<Result<Solution, RacingError>>)> {
        let n = ids.len();
        ids.into_iter()
            .enumerate()
            .map(|(j, i)| (i, run(i, n - j)))
            .collect()
    };
    let mut out: Vec<Option<Result<Solution, RacingError>>> =
        (0..starts.len()).map(|_| None).collect();
    if threads <= 1 || starts.len() < 2 {
        for (i, r) in on_thread((0..starts.len()).collect()) {
            out[i] = r;
        }
    } else {
        // the warm start (0) and the straight start (2) here, the full-lock starts (1, 3) on a
        // second thread
        let on_thread = &on_thread;
        std::thread::scope(|scope| {
            let other = scope.spawn(move || on_thread((1..starts.len()).step_by(2).collect()));
            for (i, r) in on_thread((0..starts.len()).step_by(2).collect()) {
                out[i] = r;
            }
            match other.join() {
                Ok(done) => {
                    for (i, r) in done {
                        out[i] = r;
                    }
                }
                Err(panic) => std::panic::resume_unwind(panic),
            }
        });
    }
    out.into_iter().map(Option::transpose).collect()
}
