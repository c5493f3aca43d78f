//! Prints how the fixture humanoid stands under the PD hold with no randomization (debug aid).
use randomize::{Batch, EpisodeOptions, Layout, Spec};
use std::sync::Arc;
use twin_core::mj::Model;
fn main() -> Result<(), randomize::Error> {
    let path = std::env::args()
        .nth(1)
        .unwrap_or("randomize/tests/fixtures/humanoid.xml".into());
    let model = Arc::new(Model::from_file(&path)?);
    let layout = Layout::new(&Spec::default(), &model)?;
    let options = EpisodeOptions {
        duration_secs: 2.0,
        ..EpisodeOptions::default()
    };
    let b = Batch::new(model, layout, options, 0)?;
    let mut t = randomize::episode::Trajectory::default();
    let r = randomize::Worker::new(&b)?.run(&b, 0, Some(&mut t))?;
    for row in t.rows.iter().step_by(100) {
        println!("{:?}", &row[..8]);
    }
    println!("{r:?}");
    Ok(())
}
