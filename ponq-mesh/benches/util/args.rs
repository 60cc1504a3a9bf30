//! The benchmarks' command lines: the arguments after `--`, a usage text, unknown options.

/// The arguments given after `--` (without the `--bench` that cargo adds). Prints `usage` and
/// exits for `-h` / `--help`; exits with code 2 on an option that is not in `options` (the
/// options a benchmark takes; the benchmark reads their values, if any).
pub fn parse(usage: &str, options: &[&str]) -> Vec<String> {
    let args: Vec<String> = std::env::args()
        .skip(1)
        .filter(|a| a != "--bench")
        .collect();
    if args.iter().any(|a| a == "-h" || a == "--help") {
        println!("{usage}");
        std::process::exit(0);
    }
    if let Some(bad) = args
        .iter()
        .find(|a| a.starts_with('-') && !options.contains(&a.as_str()))
    {
        eprintln!("error: unknown option {bad}\n\n{usage}");
        std::process::exit(2);
    }
    args
}
