use dynlab_control::racing::*;
use dynlab_sim::{CarInput, CarScenario, CarWorld, Track};
fn main() {
    let track = Track::from_file(std::env::args().nth(1).unwrap()).unwrap();
    let mut settings: RacerSettings = match std::env::args().nth(2) {
        Some(p) => toml::from_str(&std::fs::read_to_string(p).unwrap()).unwrap(),
        None => RacerSettings::default(),
    };
    let scenario = CarScenario::on_track(track.clone());
    settings.limits.steering_max = scenario.car.steering_max;
    settings.limits.throttle_min = scenario.car.throttle_min;
    settings.limits.throttle_max = scenario.car.throttle_max;
    let truth = SimCar::new(&scenario, 0.01).unwrap();
    let mut racer = Racer::new(&truth, &track, settings).unwrap();
    println!("profile min speed {:.2}", racer.profile().min_speed());
    let mut world = CarWorld::new(&scenario).unwrap();
    let mut input = CarInput::new(0.0, 0.0);
    let mut seg = track.locate([world.state().x, world.state().y]).segment;
    let (mut travelled, mut last_arc, mut min_b, mut laps) = (
        0.0f64,
        track.locate([world.state().x, world.state().y]).arc,
        f64::INFINITY,
        Vec::<f64>::new(),
    );
    for step in 0..2500 {
        let t = world.state();
        let s = [t.x, t.y, t.psi, t.vx, t.vy, t.omega];
        if step % 5 == 0 {
            let r = racer.step(s).unwrap();
            input = CarInput::new(r.input[0], r.input[1]);
            let l = track.locate_near([t.x, t.y], seg, 12);
            seg = l.segment;
            if step % 20 == 0 {
                println!(
                    "t {:.2} arc {:.2} lat {:+.3} v {:.2} vref {:.2} u [{:+.2} {:+.2}] {} el {} cost {:.3}",
                    world.time(),
                    l.arc,
                    l.lateral,
                    t.vx,
                    racer.profile().speed_at(l.arc),
                    r.input[0],
                    r.input[1],
                    r.status,
                    r.elastic_qps,
                    r.cost
                );
            }
        }
        world.step(input, 0.01).unwrap();
        let t = world.state();
        let l = track.locate_near([t.x, t.y], seg, 12);
        let mut d = l.arc - last_arc;
        if d > 0.5 * track.length() {
            d -= track.length();
        } else if d < -0.5 * track.length() {
            d += track.length();
        }
        travelled += d;
        last_arc = l.arc;
        min_b = min_b.min(l.half_width - l.lateral.abs());
        if travelled >= track.length() * (laps.len() + 1) as f64 {
            laps.push(world.time());
        }
    }
    println!(
        "SUMMARY laps {:?} travelled {:.2} min border {:.3}",
        laps, travelled, min_b
    );
}
