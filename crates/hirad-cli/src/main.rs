//! `hirad`: thin command-line front end of the hirad library. Parses arguments, builds a
//! configuration, calls the library, prints tables or JSON.

mod cmd;
mod progress;

use clap::{Parser, Subcommand};

/// Hierarchical radiosity with clustering.
#[derive(Parser, Debug)]
#[command(
    name = "hirad",
    version = concat!(env!("CARGO_PKG_VERSION"), " (commit ", env!("HIRAD_BUILD_COMMIT"), ")"),
    about = "hirad: hierarchical radiosity with clustering — bake diffuse lighting of a scene \
             (OBJ, glTF, PLY, TOML) into glTF/PLY, render and compare it with a path tracer, \
             and run the clustering studies of Hasenfratz et al. (EG'99)",
    long_about = None,
    after_help = EXAMPLES
)]
struct Cli {
    #[command(flatten)]
    global: Global,
    #[command(subcommand)]
    command: Command,
}

const EXAMPLES: &str = "Examples:
  hirad solve office --out out               bake radiosity: out/solution.glb, .ply, image, stats
  hirad render out/solution.glb --scene office --eye 1,-1,1.6 --image view.png
  hirad reference office --spp 256 --image ref.exr     path-traced image of the same view
  hirad diff out/image.exr ref.exr           CIELUV error (RMS ΔE*uv, mean luminance ratio)
  hirad validate office                      all of the above against two path-traced seeds
  hirad study cornell --out study            the paper's experiments, plots and report
  hirad info ../shared/scenes/bathroom/bathroom.obj --json
  hirad scene cornell --out cornell.obj      write a built-in scene to a file
  hirad clusters office --clustering all     statistics of every clustering strategy
  hirad raybench soup --clustering all --pairs 100000 --seed 1
  hirad view out/solution.glb --scene office  out/viewer.html: the solution in a browser";

/// Options every subcommand takes.
#[derive(clap::Args, Debug, Clone)]
pub struct Global {
    /// More log output (-v info, -vv debug, -vvv trace).
    #[arg(short, long, action = clap::ArgAction::Count, global = true)]
    pub verbose: u8,
    /// No progress bars, warnings and errors only.
    #[arg(short, long, global = true)]
    pub quiet: bool,
    /// Worker threads (default: all cores).
    #[arg(long, global = true)]
    pub threads: Option<usize>,
    /// Print machine-readable JSON instead of a table.
    #[arg(long, global = true)]
    pub json: bool,
}

#[derive(Subcommand, Debug)]
enum Command {
    /// Counts, area, bounding box, materials, emitters and load time of a scene.
    Info(cmd::info::Args),
    /// Write a built-in scene to a file (OBJ or glTF by extension).
    Scene(cmd::scene::Args),
    /// Build cluster hierarchies and print their statistics.
    Clusters(cmd::clusters::Args),
    /// The paper's ray-casting test: random segments cast through each cluster tree.
    Raybench(cmd::raybench::Args),
    /// Solve a scene with hierarchical radiosity and write the solution.
    Solve(cmd::solve::Args),
    /// Render images of a solution.
    Render(cmd::render::Args),
    /// CIELUV image error between an image and a reference.
    Diff(cmd::diff::Args),
    /// Path-traced reference image of a scene.
    Reference(cmd::reference::Args),
    /// The paper's experiments end to end: statistics, ray casting, ε sweeps, plots, report.
    Study(cmd::study::Args),
    /// Solve, render from the view and compare with two path-traced references.
    Validate(cmd::validate::Args),
    /// Write a self-contained HTML viewer (WebGL2) of a solution glb, or serve it on 127.0.0.1.
    View(cmd::view::Args),
}

fn main() {
    // A closed pipe (`hirad info … | head`) ends the process quietly, as it ends other Unix
    // tools, instead of a panic in `println!`.
    #[cfg(unix)]
    unsafe {
        libc::signal(libc::SIGPIPE, libc::SIG_DFL);
    }
    hirad::study::records::set_build_commit(env!("HIRAD_BUILD_COMMIT"));
    let cli = Cli::parse();
    init_logging(&cli.global);
    if let Some(n) = cli.global.threads {
        if let Err(e) = rayon::ThreadPoolBuilder::new()
            .num_threads(n)
            .build_global()
        {
            eprintln!("error: cannot set up {n} threads: {e}");
            std::process::exit(2);
        }
    }
    let r = match cli.command {
        Command::Info(a) => cmd::info::run(a, &cli.global),
        Command::Scene(a) => cmd::scene::run(a, &cli.global),
        Command::Clusters(a) => cmd::clusters::run(a, &cli.global),
        Command::Raybench(a) => cmd::raybench::run(a, &cli.global),
        Command::Solve(a) => cmd::solve::run(a, &cli.global),
        Command::Render(a) => cmd::render::run(a, &cli.global),
        Command::Diff(a) => cmd::diff::run(a, &cli.global),
        Command::Reference(a) => cmd::reference::run(a, &cli.global),
        Command::Validate(a) => cmd::validate::run(a, &cli.global),
        Command::Study(a) => cmd::study::run(a, &cli.global),
        Command::View(a) => cmd::view::run(a, &cli.global),
    };
    if let Err(e) = r {
        eprintln!("error: {e:#}");
        let input = e
            .downcast_ref::<hirad::Error>()
            .map(|e| e.is_input())
            .unwrap_or(false);
        std::process::exit(if input { 2 } else { 1 });
    }
}

fn init_logging(g: &Global) {
    let level = if g.quiet {
        "warn"
    } else {
        match g.verbose {
            0 => "warn",
            1 => "info",
            2 => "debug",
            _ => "trace",
        }
    };
    let filter = tracing_subscriber::EnvFilter::try_from_env("HIRAD_LOG")
        .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new(level));
    tracing_subscriber::fmt()
        .with_env_filter(filter)
        .with_writer(std::io::stderr)
        .with_target(false)
        .init();
}
