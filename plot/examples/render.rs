fn main() -> anyhow::Result<()> {
    let mut a = std::env::args().skip(1);
    let log = a.next().expect("log");
    let lab = a.next();
    let args =
        plot::PlotArgs { log: log.into(), out: None, lab, obstacle: vec![], checkpoint: vec![], no_summary: false };
    plot::run(&args)?;
    Ok(())
}
