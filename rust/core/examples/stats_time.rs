use std::time::Instant;
fn main() {
    let p = std::path::PathBuf::from(std::env::args().nth(1).expect("path"));
    for _ in 0..3 {
        let t = Instant::now();
        let st = blurset_core::stats::build_stats(&p).expect("stats");
        println!("build_stats {:?} {}", t.elapsed(), st.counts.views);
    }
}
