//! Debug aid: runs one passive episode through the engine and the same steps through a plain C
//! `mj_step` loop, and prints both final base positions and their times.
use randomize::{Batch, EpisodeOptions, Layout, Spec};
use std::sync::Arc;
use std::time::Instant;
use twin_core::mj::{Data, Model};
fn main() -> Result<(), randomize::Error> {
    let path = std::env::args().nth(1).unwrap_or("randomize/tests/fixtures/humanoid.xml".into());
    let model = Arc::new(Model::from_file(&path)?);
    let layout = Layout::new(&Spec::default(), &model)?;
    let options = EpisodeOptions {
        duration_secs: 5.0,
        controller: "passive".into(),
        fall_height_fraction: 0.0,
        fall_tilt_rad: 4.0,
    };
    let b = Batch::new(model.clone(), layout, options, 0)?;
    let mut w = randomize::Worker::new(&b)?;
    for _ in 0..3 {
        let t = Instant::now();
        let mut traj = randomize::episode::Trajectory::default();
        let r = w.run(&b, 0, Some(&mut traj))?;
        let e = t.elapsed();
        let t = Instant::now();
        let mut d = Data::new(model.clone())?;
        twin_core::control::reset_to_home(&mut d)?;
        twin_core::mj::bench_c_step_loop(&mut d, b.steps_per_episode());
        let c = t.elapsed();
        let t = Instant::now();
        let _ = w.run(&b, 0, None)?;
        let e2 = t.elapsed();
        println!(
            "engine(rec) {e:?} engine {e2:?} C {c:?}; engine end {:?} C end {:?} ncon {} tilt {}",
            &traj.rows.last().unwrap()[1..4],
            d.xpos()[1],
            d.ncon(),
            r.max_tilt_rad
        );
    }
    Ok(())
}
