//! The offline manoeuvres' gradient descent: the chunked, threaded line search is the paper's
//! single batched line search.

use dynlab_control::racing::{
    GdSettings, Input, InputLimits, Manoeuvre, Plant, gradient, solve_gd, true_car_model,
};
use dynlab_sim::car::CarParams;

/// The paper's iteration written out with one batched rollout of every candidate.
fn reference_gd(
    problem: &dynlab_control::racing::Problem<'_>,
    initial: &[Input],
    settings: &GdSettings,
) -> (Vec<Input>, f64) {
    let mut u = initial.to_vec();
    let (mut cost, mut grad, _) = gradient(problem, &u).unwrap();
    let m = settings.step_sizes;
    let ratio = (settings.smallest_step / settings.largest_step).powf(1.0 / (m - 1) as f64);
    for _ in 0..settings.iterations {
        let cands: Vec<Vec<Input>> = (0..m)
            .map(|i| {
                let a = settings.largest_step * ratio.powi(i as i32);
                u.iter()
                    .zip(&grad)
                    .map(|(x, g)| [x[0] - a * g[0], x[1] - a * g[1]])
                    .collect()
            })
            .collect();
        let rolled = problem.plant.rollout_batch(&problem.s0, &cands).unwrap();
        let mut best = (cost, usize::MAX);
        for (i, (c, s)) in cands.iter().zip(&rolled).enumerate() {
            let v = problem.objective.cost(s, c);
            if v < best.0 {
                best = (v, i);
            }
        }
        if best.1 == usize::MAX {
            break;
        }
        u = cands[best.1].clone();
        (cost, grad, _) = gradient(problem, &u).unwrap();
    }
    (u, cost)
}

#[test]
fn chunked_line_search_matches_one_batch_of_all_512_step_sizes() {
    let model = true_car_model(&CarParams::default(), 0.01).unwrap();
    let plant = Plant::new(&model, 5).unwrap();
    let m = Manoeuvre::drifting_turn();
    let problem = m.problem(plant, [0.0; 6], InputLimits::default());
    let settings = GdSettings {
        iterations: 4,
        ..GdSettings::default()
    };
    assert_eq!(settings.step_sizes, 512);
    let gd = solve_gd(&problem, &m.initial_inputs(), &settings).unwrap();
    let (u, cost) = reference_gd(&problem, &m.initial_inputs(), &settings);
    assert!(gd.cost < gd.history[0], "descent: {:?}", gd.history);
    assert_eq!(gd.iterations, 4);
    assert!(
        (gd.cost - cost).abs() <= 1e-12 * cost.abs(),
        "{} vs {cost}",
        gd.cost
    );
    for (a, b) in gd.inputs.iter().zip(&u) {
        assert_eq!(a, b);
    }
    // and it is repeatable
    let again = solve_gd(&problem, &m.initial_inputs(), &settings).unwrap();
    assert_eq!(again.inputs, gd.inputs);
}
