//! Exit codes, in one place: each library operation's typed error (and the located diagnostic
//! of the crates that still return one) mapped to the code a script acts on.
//!
//! 0 done; 1 a batch finished but some parts failed (decided by the batch's summary);
//! 2 fix the input: bad file content, options or settings, data a method cannot use, a file
//! that cannot be read; 3 the machine or errmap: an output that cannot be written, the GPU,
//! an internal error.

use errmap::batch::{ClusterError, FolderError, JobError, MergeError, RunError, ShardError};
use errmap::circular::CircularError;
use errmap::controller::TableError;
use errmap::error::{Diagnose, Diagnostic};
use errmap::linear::LinearError;
use errmap::live::{ConfigError, LinkError, LiveError};
use errmap::map::grid_file::GridError;
use errmap::map::MapError;
use errmap::probe::ProbeError;
use errmap::report::ReportError;
use errmap::rotary::RotaryError;
use errmap::serve::{ServeError, UsersError};
use errmap::synth::SynthError;
use errmap::thermal::ThermalError;
use errmap::toolpath::{CompensateError, DialectError, SettingsError};

/// Bad input: the user fixes a file, an option or a setting.
const INPUT: i32 = 2;
/// The machine (an output, the GPU) or errmap itself.
const SYSTEM: i32 = 3;

/// Declares [`Failure`], one variant per error type, with `From` each type (so `?` works in a
/// command), the diagnostic it prints, and the boxed live loop's error beside them.
macro_rules! failures {
    ($($(#[$doc:meta])* $variant:ident($ty:ty),)+) => {
        /// Why a command failed: the typed error of the library operation it called, or a located
        /// diagnostic (the CLI's own checks, and the crates that still return one).
        #[derive(Debug)]
        pub enum Failure {
            $($(#[$doc])* $variant($ty),)+
            /// The live loop (boxed: its source and target errors nest one level deeper).
            Live(Box<LiveError>),
        }
        errmap_core::typed_error!(Failure { $($variant,)+ Live });
        $(impl From<$ty> for Failure {
            fn from(e: $ty) -> Self {
                Failure::$variant(e)
            }
        })+
    };
}
failures!(
    /// A located diagnostic (the CLI's own checks).
    Diagnostic(Diagnostic),
    /// A job file (`errmap batch`, `slurm`, `k8s`, `merge --job`).
    Job(JobError),
    /// A shard named on the command line or by the scheduler.
    Shard(ShardError),
    /// A batch run or one part's map (`errmap batch`, `errmap map`).
    Run(RunError),
    /// The merge of a sharded job (`errmap merge`), boxed: its run and job errors nest two
    /// levels deeper.
    Merge(Box<MergeError>),
    /// Slurm scripts or Kubernetes manifests (`errmap slurm`, `errmap k8s`).
    Cluster(ClusterError),
    /// A run folder's report (`errmap report`).
    Folder(FolderError),
    /// Compensation settings in words (`errmap compensate`'s flags).
    Settings(SettingsError),
    /// Toolpath compensation.
    Compensate(CompensateError),
    /// Reading a probe file.
    Probe(ProbeError),
    /// Reading or using a fitted map.
    Map(MapError),
    /// Probe points onto a grid (`errmap grid`).
    Grid(GridError),
    /// A linear-axis analysis.
    Linear(LinearError),
    /// A thermal command.
    Thermal(ThermalError),
    /// A rotary-axis analysis or table.
    Rotary(RotaryError),
    /// A circular test.
    Circular(CircularError),
    /// A controller compensation table.
    Table(TableError),
    /// A report: results read back, the PDF.
    Report(ReportError),
    /// Sample data (`errmap synth …`).
    Synth(SynthError),
    /// A live config (`errmap live CONFIG`).
    LiveConfig(ConfigError),
    /// The monitor's users file (`errmap serve user …`, and at the server's start).
    Users(UsersError),
    /// The monitor (`errmap serve`).
    Serve(ServeError),
);

impl From<MergeError> for Failure {
    fn from(e: MergeError) -> Self {
        Failure::Merge(Box::new(e))
    }
}

impl From<LiveError> for Failure {
    fn from(e: LiveError) -> Self {
        Failure::Live(Box::new(e))
    }
}

/// A command's result: its exit code, or why it failed.
pub type Result<T, E = Failure> = std::result::Result<T, E>;

/// An analysis' error (they share their variants): bad options, a bad line or file, a fit
/// not possible or an unreadable input are the input's; an output, a bug the machine's or
/// errmap's.
macro_rules! analysis {
    ($ty:ident, $e:expr) => {
        match $e {
            $ty::Options(_) | $ty::Line(_) | $ty::File(_) | $ty::Fit(_) | $ty::Read(_) => INPUT,
            $ty::Write(_) | $ty::Internal(_) => SYSTEM,
            other => diagnostic(other.diagnostic()),
        }
    };
}

/// The exit code of a failed command.
pub fn code(failure: &Failure) -> i32 {
    let code = match failure {
        Failure::Diagnostic(d) => diagnostic(d),
        Failure::Job(e) => job(e),
        Failure::Shard(_) => INPUT,
        Failure::Run(e) => run(e),
        Failure::Merge(e) => merge(e),
        Failure::Cluster(e) => cluster(e),
        Failure::Folder(e) => folder(e),
        Failure::Settings(_) => INPUT,
        Failure::Compensate(e) => compensate(e),
        Failure::Probe(e) => probe(e),
        Failure::Map(e) => map(e),
        Failure::Grid(e) => grid(e),
        Failure::Linear(e) => analysis!(LinearError, e),
        Failure::Thermal(e) => analysis!(ThermalError, e),
        Failure::Rotary(e) => analysis!(RotaryError, e),
        Failure::Circular(e) => analysis!(CircularError, e),
        Failure::Table(e) => analysis!(TableError, e),
        Failure::Report(e) => report(e),
        Failure::Synth(e) => synth(e),
        Failure::LiveConfig(e) => live_config(e),
        Failure::Live(e) => live(e),
        Failure::Users(e) => users(e),
        Failure::Serve(e) => serve(e),
    };
    // Every typed variant keeps the code its diagnostic's kind had before the types existed.
    debug_assert_eq!(code, diagnostic(failure.diagnostic()), "{failure}");
    code
}

/// A diagnostic by its kind: bad input, usage, a numeric failure or an unreadable file are the
/// input's; any other I/O failure, the device and internal errors are the machine's or errmap's.
fn diagnostic(d: &Diagnostic) -> i32 {
    match d {
        Diagnostic::Input { .. } | Diagnostic::Usage { .. } | Diagnostic::Numeric { .. } => INPUT,
        Diagnostic::Io { .. } if d.is_read() => INPUT,
        Diagnostic::Io { .. } | Diagnostic::Device { .. } | Diagnostic::Internal(_) => SYSTEM,
    }
}

fn job(e: &JobError) -> i32 {
    use JobError as E;
    match e {
        E::Toml(_) | E::Value(_) | E::Probes(_) | E::Read(_) => INPUT,
        E::Internal(_) => SYSTEM,
        _ => diagnostic(e.diagnostic()),
    }
}

/// A run: its job, options, inputs and output folder are the user's to fix; an output that
/// cannot be written, the device and a bug are not.
fn run(e: &RunError) -> i32 {
    use RunError as E;
    match e {
        E::Job(j) => job(j),
        E::Options(_) | E::Input(_) | E::Output(_) | E::Read(_) => INPUT,
        E::Write(_) | E::Device(_) | E::Internal(_) => SYSTEM,
        _ => diagnostic(e.diagnostic()),
    }
}

fn merge(e: &MergeError) -> i32 {
    use MergeError as E;
    match e {
        E::Job(j) => job(j),
        E::Run(r) => run(r),
        E::Missing(_) | E::Split(_) | E::Mismatch(_) | E::Read(_) => INPUT,
        E::Internal(_) => SYSTEM,
        _ => diagnostic(e.diagnostic()),
    }
}

/// No Slurm here is the user's to fix (submit elsewhere); a refused submission is the
/// cluster's.
fn cluster(e: &ClusterError) -> i32 {
    use ClusterError as E;
    match e {
        E::Array(_) | E::NoScheduler(_) => INPUT,
        E::Submit(_) | E::Write(_) | E::Internal(_) => SYSTEM,
        _ => diagnostic(e.diagnostic()),
    }
}

fn folder(e: &FolderError) -> i32 {
    use FolderError as E;
    match e {
        E::Result(r) => report(r),
        E::NotARun(_) | E::File(_) | E::Read(_) => INPUT,
        E::Write(_) | E::Internal(_) => SYSTEM,
        _ => diagnostic(e.diagnostic()),
    }
}

fn compensate(e: &CompensateError) -> i32 {
    use CompensateError as E;
    match e {
        E::Settings(_)
        | E::Dialect(DialectError::Uncertain(_))
        | E::Program(_)
        | E::Uncovered(_)
        | E::Overwrite(_)
        | E::Read(_) => INPUT,
        E::Write(_) | E::Internal(_) => SYSTEM,
        _ => diagnostic(e.diagnostic()),
    }
}

fn probe(e: &ProbeError) -> i32 {
    use ProbeError as E;
    match e {
        E::Options(_) | E::Line(_) | E::File(_) | E::Read(_) => INPUT,
        E::Write(_) | E::Internal(_) => SYSTEM,
        _ => diagnostic(e.diagnostic()),
    }
}

fn map(e: &MapError) -> i32 {
    use MapError as E;
    match e {
        E::Options(_) | E::Line(_) | E::File(_) | E::Implausible(_) | E::Weak(_) | E::Read(_) => {
            INPUT
        }
        E::Write(_) | E::Internal(_) => SYSTEM,
        _ => diagnostic(e.diagnostic()),
    }
}

fn grid(e: &GridError) -> i32 {
    use GridError as E;
    match e {
        E::Probes(p) => probe(p),
        E::Options(_) => INPUT,
        E::Write(_) | E::Internal(_) => SYSTEM,
        _ => diagnostic(e.diagnostic()),
    }
}

fn report(e: &ReportError) -> i32 {
    use ReportError as E;
    match e {
        E::NoBrowser(_) | E::Output(_) | E::Result(_) | E::Read(_) => INPUT,
        E::Print(_) | E::Write(_) | E::Internal(_) => SYSTEM,
        _ => diagnostic(e.diagnostic()),
    }
}

fn synth(e: &SynthError) -> i32 {
    use SynthError as E;
    match e {
        E::Options(_) | E::Input(_) | E::Read(_) => INPUT,
        E::Write(_) | E::Internal(_) => SYSTEM,
        _ => diagnostic(e.diagnostic()),
    }
}

fn live_config(e: &ConfigError) -> i32 {
    use ConfigError as E;
    match e {
        E::Read(_) | E::Key(_) => INPUT,
        E::Internal(_) => SYSTEM,
        _ => diagnostic(e.diagnostic()),
    }
}

/// A source or target: its keys and its login are the config's to fix; a machine that cannot
/// be reached is not the input's fault.
fn link(e: &LinkError) -> i32 {
    use LinkError as E;
    match e {
        E::Config(_) | E::Refused(_) => INPUT,
        E::Unreachable(_) | E::Internal(_) => SYSTEM,
        _ => diagnostic(e.diagnostic()),
    }
}

fn live(e: &LiveError) -> i32 {
    use LiveError as E;
    match e {
        E::Config(_) | E::Model(_) | E::Store(_) => INPUT,
        E::Source(l) | E::Target(l) => link(l),
        E::Record(_) | E::Internal(_) => SYSTEM,
        _ => diagnostic(e.diagnostic()),
    }
}

fn users(e: &UsersError) -> i32 {
    use UsersError as E;
    match e {
        E::Missing(_) | E::Read(_) | E::File(_) | E::Name(_) | E::Password(_) | E::Output(_) => {
            INPUT
        }
        E::Write(_) | E::Internal(_) => SYSTEM,
        _ => diagnostic(e.diagnostic()),
    }
}

fn serve(e: &ServeError) -> i32 {
    use ServeError as E;
    match e {
        E::Transport(_) | E::Runs(_) | E::Store(_) | E::Tls(_) => INPUT,
        E::Users(u) => users(u),
        E::Bind(_) | E::Internal(_) => SYSTEM,
        _ => diagnostic(e.diagnostic()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use errmap::error::Location;
    use std::io;

    fn input() -> Diagnostic {
        Diagnostic::input(Location::line("p.csv", 3), "bad", "fix it")
    }
    fn read() -> Diagnostic {
        Diagnostic::read("p.csv", io::Error::from(io::ErrorKind::NotFound))
    }
    fn write() -> Diagnostic {
        Diagnostic::write("out.csv", io::Error::from(io::ErrorKind::PermissionDenied))
    }
    fn unreachable() -> Diagnostic {
        Diagnostic::io(
            "reach",
            "Modbus source 'rack'",
            io::Error::from(io::ErrorKind::ConnectionRefused),
        )
    }

    /// The codes of the documented table (the module page): 2 for the input's faults, 3 for
    /// the machine's or errmap's, whatever operation reported them.
    #[test]
    fn each_operation_keeps_the_documented_codes() {
        let cases: Vec<(Failure, i32)> = vec![
            (Failure::from(input()), 2),
            (Failure::from(read()), 2),
            (Failure::from(write()), 3),
            (Failure::from(Diagnostic::Internal("x".into())), 3),
            (Failure::from(Diagnostic::device("lost", "")), 3),
            (CompensateError::from(input()).into(), 2),
            (CompensateError::from(read()).into(), 2),
            (CompensateError::from(write()).into(), 3),
            (CompensateError::Overwrite(input()).into(), 2),
            (ProbeError::from(read()).into(), 2),
            (ProbeError::from(write()).into(), 3),
            (MapError::Weak(input()).into(), 2),
            (GridError::from(ProbeError::from(read())).into(), 2),
            (
                LinearError::from(Diagnostic::numeric("singular", "")).into(),
                2,
            ),
            (ThermalError::from(write()).into(), 3),
            (TableError::from(input()).into(), 2),
            (
                ReportError::from(Diagnostic::device("no PDF", "")).into(),
                3,
            ),
            (ReportError::from(read()).into(), 2),
            (SynthError::from(write()).into(), 3),
            (SynthError::from(Diagnostic::usage("bad", "")).into(), 2),
            (ConfigError::from(input()).into(), 2),
            (ConfigError::from(read()).into(), 2),
            (LiveError::from(input()).into(), 2),
            (LiveError::Model(read()).into(), 2),
            (LiveError::Source(LinkError::from(input())).into(), 2),
            (LiveError::Target(LinkError::Refused(input())).into(), 2),
            (
                LiveError::Source(LinkError::Unreachable(unreachable())).into(),
                3,
            ),
            (LiveError::Target(LinkError::from(unreachable())).into(), 3),
            (LiveError::Store(input()).into(), 2),
            (LiveError::Record(write()).into(), 3),
            (UsersError::Missing(read()).into(), 2),
            (UsersError::Name(Diagnostic::usage("no user", "")).into(), 2),
            (UsersError::Write(write()).into(), 3),
            (ServeError::Tls(read()).into(), 2),
            (ServeError::Store(input()).into(), 2),
            (ServeError::Users(UsersError::File(input())).into(), 2),
            (ServeError::Bind(unreachable()).into(), 3),
            (JobError::Toml(input()).into(), 2),
            (JobError::from(read()).into(), 2),
            (
                ShardError::Spec(Diagnostic::usage("--shard 3/3", "")).into(),
                2,
            ),
            (RunError::from(JobError::Probes(input())).into(), 2),
            (RunError::Output(Diagnostic::usage("taken", "")).into(), 2),
            (RunError::from(read()).into(), 2),
            (RunError::from(write()).into(), 3),
            (RunError::from(Diagnostic::device("lost", "")).into(), 3),
            (
                MergeError::Missing(Diagnostic::usage("shards [1] of 2", "")).into(),
                2,
            ),
            (MergeError::from(input()).into(), 2),
            (MergeError::from(write()).into(), 3),
            (
                ClusterError::NoScheduler(Diagnostic::usage("no sbatch", "")).into(),
                2,
            ),
            (
                ClusterError::Submit(Diagnostic::device("sbatch failed", "")).into(),
                3,
            ),
            (ClusterError::from(write()).into(), 3),
            (
                FolderError::NotARun(Diagnostic::usage("no run", "")).into(),
                2,
            ),
            (FolderError::from(ReportError::from(read())).into(), 2),
        ];
        for (failure, expected) in cases {
            assert_eq!(code(&failure), expected, "{failure:?}");
        }
    }

    /// A typed error prints exactly its diagnostic, causes included.
    #[test]
    fn a_typed_error_prints_its_diagnostic_word_for_word() {
        let typed = Failure::from(CompensateError::from(read()));
        let plain = read();
        assert_eq!(typed.to_string(), "cannot read p.csv: entity not found");
        assert_eq!(typed.to_string(), plain.to_string());
        let cause = std::error::Error::source(&typed).map(|c| c.to_string());
        assert_eq!(cause.as_deref(), Some("entity not found"));
    }
}
