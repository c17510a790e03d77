//! Takes a screenshot of a running viewer's page in headless Chromium, as the guide's figures
//! were made: `cargo run --release --example screenshot -- URL OUT.png [WIDTH HEIGHT]`.
//! It waits until the page has the world and has drawn for a second, in real time.

use std::time::Duration;

use bench_harness::browser::Browser;

fn main() -> anyhow::Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let [url, out, rest @ ..] = args.as_slice() else {
        anyhow::bail!("usage: screenshot URL OUT.png [WIDTH HEIGHT]");
    };
    let size = |k: usize, d: u32| rest.get(k).and_then(|v| v.parse().ok()).unwrap_or(d);
    let mut b = Browser::launch(size(0, 1280), size(1, 560))?;
    b.navigate(url)?;
    b.wait_for("window.iwsim.frame && window.iwsim.draws > 0", Duration::from_secs(30))?;
    // A second and a half of drawing, so the rate counters on screen are real.
    let until = b.eval("performance.now()")?.as_f64().unwrap_or(0.0) + 1500.0;
    b.wait_for(&format!("performance.now() > {until}"), Duration::from_secs(30))?;
    std::fs::write(out, b.screenshot_png()?)?;
    println!("{out}");
    Ok(())
}
