//! `cargo run --release -p vge-sim --example bench [control_hz physics_hz iterations]`
fn main() {
    let args: Vec<f32> = std::env::args().skip(1).filter_map(|a| a.parse().ok()).collect();
    let mut s = vge_sim::bench::BenchSettings::default();
    if let [c, p, it, pd] = args[..] {
        s.env.physics.contact_prediction_distance_m = pd;
        s.env.control_hz = c;
        s.env.physics.physics_hz = p;
        s.env.physics.solver_iterations = it as usize;
    }
    match vge_sim::bench::run(&s) {
        Ok(b) => println!("{}", b.to_json_line()),
        Err(e) => eprintln!("{e}"),
    }
}
