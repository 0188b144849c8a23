//! `scbg`: the command line over the `scbg` library. Parses arguments, calls the library,
//! shows progress, prints results, and turns errors into one message and exit code 2.

mod cli;
mod cmd;
mod progress;

use clap::Parser;

/// mimalloc keeps freed memory for reuse; with glibc's allocator every large tensor temporary
/// was returned to the OS and faulted back in on the next op (~12 % of a training step).
#[global_allocator]
static GLOBAL: mimalloc::MiMalloc = mimalloc::MiMalloc;

/// mimalloc's `purge_delay` option (index in mimalloc v3's `mi_option_e`; libmimalloc-sys names
/// no constant for it).
const MI_OPTION_PURGE_DELAY: libmimalloc_sys::mi_option_t = 15;

fn main() {
    let args = cli::Cli::parse();
    // Never hand freed memory back to the OS: by default mimalloc purges it after a second, and
    // the next large tensor then faults fresh (2 MiB, zeroed) pages back in: ~3,000 faults per
    // 40 training steps and up to a tenth of a step. With purging off the process keeps its peak,
    // which suits a batch job, not a server that runs for days: a server purges what it has not
    // reused for a second (mimalloc's own default, 10 ms, costs a third more at p99).
    let purge_delay_ms = if args.command.is_server() { 1000 } else { -1 };
    // SAFETY: sets a plain integer option; valid at any time.
    #[allow(unsafe_code)]
    unsafe {
        libmimalloc_sys::mi_option_set(MI_OPTION_PURGE_DELAY, purge_delay_ms)
    };
    // Before any thread starts (scbg::fp): training otherwise takes up to 1.7× as long on an
    // Intel core as values turn subnormal. Threads started below carry the mode over.
    if !scbg::fp::keep_subnormals_requested() {
        scbg::fp::flush_subnormals();
    }
    tracing_subscriber::fmt()
        .with_env_filter(
            tracing_subscriber::EnvFilter::try_from_env("SCBG_LOG")
                .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new("info")),
        )
        .with_writer(std::io::stderr)
        .with_target(false)
        .init();
    let mode = scbg::fp::Mode::current();
    let mut pool = rayon::ThreadPoolBuilder::new().start_handler(move |_| mode.apply());
    if let Some(threads) = args.threads {
        pool = pool.num_threads(threads);
    }
    // Ignore the error: the global pool can only be built once (tests call main twice).
    let _ = pool.build_global();
    if let Err(err) = cmd::run(args.command) {
        // A closed stdout (`scbg data inspect ... | head`) ends the command quietly.
        let broken_pipe = err.chain().any(|e| {
            e.downcast_ref::<std::io::Error>()
                .is_some_and(|io| io.kind() == std::io::ErrorKind::BrokenPipe)
        });
        if broken_pipe {
            std::process::exit(0);
        }
        eprintln!("error: {err:#}");
        std::process::exit(2);
    }
}
