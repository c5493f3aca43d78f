use std::sync::Arc;
use twin_core::control::*;
use twin_core::mj::{Data, Model};
fn main() {
    let path = std::env::args().nth(1).unwrap();
    let model = Arc::new(Model::from_file(&path).unwrap());
    let mut data = Data::new(model.clone()).unwrap();
    reset_to_home(&mut data).unwrap();
    let act = Actuation::of(&model);
    let mut c = PdHold::new(&model, PdHoldOptions::default());
    c.reset(&model, &Observation::of(&data)).unwrap();
    println!("gains {:?}", c.gains());
    let mut cmd = vec![0.0; act.len(&model)];
    let base = base_body(&model);
    let t0 = std::time::Instant::now();
    for i in 0..5000 {
        c.compute(&model, &Observation::of(&data), &mut cmd);
        act.apply(&mut data, &cmd);
        data.step().unwrap();
        if i % 500 == 0 {
            if let Some(b) = base {
                println!(
                    "t {:.2} base {:?} ncon {}",
                    data.time_secs(),
                    data.xpos()[b],
                    data.ncon()
                );
            }
        }
    }
    println!("{:?} per step", t0.elapsed() / 5000);
}
