//! The `modesuite` binary: see `modesuite --help` and the README.

use clap::Parser;

fn main() {
    // before any thread starts: headless runs print no Wayland probe errors
    modesuite_render::gpu::quiet_device_select_without_session();
    let cli = modesuite::cli::Cli::parse();
    let stdout = std::io::stdout();
    let mut out = stdout.lock();
    if let Err(e) = modesuite::cli::run_cli(cli, &mut out) {
        drop(out);
        eprintln!("error: {}", e.message);
        std::process::exit(e.code);
    }
}
