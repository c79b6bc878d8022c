use dynlab_control::racing::*;
use dynlab_sim::{CarScenario, Track};
fn main() {
    let a: Vec<String> = std::env::args().collect();
    let track = Track::from_file(&a[1]).unwrap();
    let sc = CarScenario::on_track(track.clone());
    let sim = SimCar::new(&sc, 0.01).unwrap();
    let learned = a.get(6).map(|p| {
        dynlab_learn::load_model(std::path::Path::new(p), None, None)
            .unwrap()
            .0
    });
    let model: &dyn CarDynamics = match &learned {
        Some(m) => m,
        None => &sim,
    };
    let mut st = RacerSettings::default();
    st.sqp.iterations = a[2].parse().unwrap();
    st.progress_weight = a[3].parse().unwrap();
    st.reference_weight = a[4].parse().unwrap();
    st.reference_speed = a[5].parse().unwrap();
    let mut racer = Racer::new(model, &track, st).unwrap();
    let t0 = std::time::Instant::now();
    let r = run_laps(
        &mut racer,
        &sc,
        &track,
        &LapSettings {
            laps: 2,
            max_time: 40.0,
            seed: 0,
            estimate: true,
        },
        || t0.elapsed().as_secs_f64(),
    )
    .unwrap();
    println!(
        "laps {:?} exc {} off {:.2} mind {:.3} top {:.2} p50 {:.1}ms p99 {:.1}ms st {:?} el {} t {:.1}",
        r.lap_times,
        r.excursions,
        r.time_off_track,
        r.min_border_distance,
        r.top_speed,
        1e3 * r.solve_quantile(0.5),
        1e3 * r.solve_quantile(0.99),
        r.statuses,
        r.elastic_qps,
        r.time
    );
}
