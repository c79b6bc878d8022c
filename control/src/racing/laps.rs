//! Closed-loop laps: the racer against the simulator, in process.

use dynlab_learn::dynamics::data::SavGol;
use dynlab_sim::{CarInput, CarScenario, CarWorld, SimRng, Track};

use super::estimate::CarStateEstimator;
use super::race::Racer;
use super::{RacingError, SolveStatus};

/// Settings of a closed-loop run.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default)]
pub struct LapSettings {
    /// Laps to drive. Default 2.
    pub laps: usize,
    /// Give up after this much simulated time \[s\]. Default 60.
    pub max_time: f64,
    /// Seed of the pose measurement noise. Default 0.
    pub seed: u64,
    /// Estimate velocities from noisy poses (true) or use the simulator's true state (false).
    /// Default true.
    pub estimate: bool,
}

impl Default for LapSettings {
    fn default() -> Self {
        Self {
            laps: 2,
            max_time: 60.0,
            seed: 0,
            estimate: true,
        }
    }
}

/// One sample of the driven line.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct TracePoint {
    /// Time \[s\].
    pub t: f64,
    /// Position x \[m\].
    pub x: f64,
    /// Position y \[m\].
    pub y: f64,
    /// Speed \[m/s\].
    pub speed: f64,
}

/// What a closed-loop run measured.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct LapReport {
    /// Time of each completed lap \[s\] (the first from a standing start).
    pub lap_times: Vec<f64>,
    /// Simulated time driven \[s\].
    pub time: f64,
    /// Times the car's centre left the track.
    pub excursions: usize,
    /// Time spent off the track \[s\].
    pub time_off_track: f64,
    /// Smallest distance of the car's centre to a border \[m\] (negative: off the track).
    pub min_border_distance: f64,
    /// Wall-clock time of every solve \[s\] (from the caller's clock).
    pub solve_times: Vec<f64>,
    /// Solves per status `[solved, max-iterations, infeasible, numerical-error, model-failure]`
    /// (a solve stopped at the racer's `solve_budget` counts as max-iterations; see
    /// [`LapReport::deadlines`]).
    pub statuses: [usize; 5],
    /// QPs that needed the elastic fallback.
    pub elastic_qps: usize,
    /// Cycles whose plan came from a recovery start (the racer had stalled).
    #[serde(default)]
    pub recoveries: usize,
    /// Cycles in which a solve stopped at the racer's `solve_budget`
    /// ([`RaceStep::deadline`](super::RaceStep::deadline)).
    #[serde(default)]
    pub deadlines: usize,
    /// Top speed \[m/s\].
    pub top_speed: f64,
    /// The driven line, one point per model step.
    pub trace: Vec<TracePoint>,
}

impl LapReport {
    /// Quantile `q ∈ [0, 1]` of the solve times \[s\] (nearest rank; 0 without solves).
    pub fn solve_quantile(&self, q: f64) -> f64 {
        if self.solve_times.is_empty() {
            return 0.0;
        }
        let mut v = self.solve_times.clone();
        v.sort_by(f64::total_cmp);
        let i = ((q.clamp(0.0, 1.0) * v.len() as f64).ceil() as usize).clamp(1, v.len()) - 1;
        v[i]
    }
}

/// Drives `settings.laps` laps of `track` in the simulator world of `scenario` with `racer`:
/// poses are measured (with the scenario's noise) at every model step, the state is estimated
/// causally, and the racer re-solves every `hold` model steps; its input is held meanwhile
/// (the solve is assumed instantaneous). `clock` is read before and after each solve (wall
/// time in seconds, supplied by the caller: the library reads no clock).
pub fn run_laps(
    racer: &mut Racer<'_>,
    scenario: &CarScenario,
    track: &Track,
    settings: &LapSettings,
    mut clock: impl FnMut() -> f64,
) -> Result<LapReport, RacingError> {
    let mut world = CarWorld::new(scenario)?;
    let mut rng = SimRng::new(settings.seed);
    let mut est = CarStateEstimator::new(SavGol::default());
    let hold = racer.settings().hold;
    let dt = racer.period() / hold as f64;
    let len = track.length();
    let mut rep = LapReport {
        lap_times: Vec::new(),
        time: 0.0,
        excursions: 0,
        time_off_track: 0.0,
        min_border_distance: f64::INFINITY,
        solve_times: Vec::new(),
        statuses: [0; 5],
        elastic_qps: 0,
        recoveries: 0,
        deadlines: 0,
        top_speed: 0.0,
        trace: Vec::new(),
    };
    let start = world.state();
    let mut loc = track.locate([start.x, start.y]);
    let mut travelled = 0.0;
    let mut last_lap = 0.0;
    let mut off = false;
    let mut input = CarInput::new(0.0, 0.0);
    let mut step = 0usize;
    racer.reset();
    while rep.lap_times.len() < settings.laps && world.time() < settings.max_time {
        let truth = world.state();
        let pose = world.measure(&mut rng);
        let pose = [pose.x, pose.y, pose.theta];
        let s = est.observe(settings.estimate, world.time(), pose, &truth, &start);
        if step.is_multiple_of(hold) {
            let t0 = clock();
            let r = racer.step(s)?;
            rep.solve_times.push(clock() - t0);
            rep.statuses[match r.status {
                SolveStatus::Solved => 0,
                SolveStatus::MaxIterations => 1,
                SolveStatus::Infeasible => 2,
                SolveStatus::NumericalError => 3,
                SolveStatus::ModelFailure => 4,
                // stopped early, as at the iteration limit
                SolveStatus::Deadline => 1,
            }] += 1;
            rep.deadlines += usize::from(r.deadline);
            rep.elastic_qps += r.elastic_qps;
            rep.recoveries += usize::from(r.recovered);
            input = CarInput::new(r.input[0], r.input[1]);
        }
        let next = world.step(input, dt)?;
        step += 1;
        let nl = track.locate_near([next.x, next.y], loc.segment, 12);
        let mut d = nl.arc - loc.arc;
        if d > 0.5 * len {
            d -= len;
        } else if d < -0.5 * len {
            d += len;
        }
        travelled += d;
        loc = nl;
        let border = nl.half_width - nl.lateral.abs();
        rep.min_border_distance = rep.min_border_distance.min(border);
        if border < 0.0 {
            rep.time_off_track += dt;
            if !off {
                rep.excursions += 1;
            }
        }
        off = border < 0.0;
        rep.top_speed = rep.top_speed.max(next.speed());
        rep.trace.push(TracePoint {
            t: world.time(),
            x: next.x,
            y: next.y,
            speed: next.speed(),
        });
        if travelled >= len * (rep.lap_times.len() + 1) as f64 {
            rep.lap_times.push(world.time() - last_lap);
            last_lap = world.time();
        }
    }
    rep.time = world.time();
    Ok(rep)
}
