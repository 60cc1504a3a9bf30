//! Draws the loss curves of a `metrics.csv`: `cargo run -p ponq-train --example plot_losses -- metrics.csv out.png`.
fn main() -> anyhow::Result<()> {
    let args: Vec<String> = std::env::args().collect();
    anyhow::ensure!(args.len() == 3, "usage: plot_losses METRICS.csv OUT.png");
    ponq_train::plot::plot_losses(args[1].as_ref(), args[2].as_ref())
}
