//! `lightpose`: the operator command. Thin: it parses arguments, calls the
//! libraries and maps errors to one line and an exit code.

mod bench;
mod calibrate;
mod convert;
mod crb;
mod fake_autopilot;
mod guard;
mod montecarlo;
mod recover;
mod replay;
mod simulate;
mod stdout;

use clap::{Parser, Subcommand};
use std::process::ExitCode;

#[derive(Parser)]
#[command(
    name = "lightpose",
    version,
    about = "Simulate, calibrate, replay and analyse the lightpose detector array"
)]
struct Cli {
    #[command(subcommand)]
    cmd: Cmd,
}

#[derive(Subcommand)]
enum Cmd {
    /// Simulate a trajectory through a scene and write an intensity log.
    Simulate(simulate::SimulateArgs),
    /// Write the calibration sweeps of MODEL.md as an intensity log.
    Sweep(simulate::SweepArgs),
    /// Fit a calibration from truth-labelled sweep logs.
    Calibrate(calibrate::CalibrateArgs),
    /// Run an estimator over a recorded log and write POSE lines.
    Replay(replay::ReplayArgs),
    /// Monte Carlo uncertainty of an estimator along a trajectory.
    Montecarlo(montecarlo::MontecarloArgs),
    /// Trade table: every estimator's speed, accuracy and honesty on the paper's cases, per set of own sensors.
    Bench(bench::BenchArgs),
    /// Cramér–Rao bound of a scene along a trajectory, one row per frame.
    Crb(crb::CrbArgs),
    /// Convert an intensity log between JSON Lines and MCAP, or with its
    /// poses into a ROS 2 bag (--ros2).
    Convert(convert::ConvertArgs),
    /// Rewrite an MCAP cut short (kill -9, power loss) as a finished file
    /// that every reader opens, with every whole record written.
    Recover(recover::RecoverArgs),
    /// Stand in for the vehicle's autopilot: send its sensors over MAVLink
    /// from a trajectory and check the daemon's poses against the truth.
    FakeAutopilot(fake_autopilot::FakeAutopilotArgs),
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    let r = match cli.cmd {
        Cmd::Simulate(a) => simulate::simulate(a),
        Cmd::Sweep(a) => simulate::sweep(a),
        Cmd::Calibrate(a) => calibrate::run(a),
        Cmd::Replay(a) => replay::run(a),
        Cmd::Montecarlo(a) => montecarlo::run(a),
        Cmd::Bench(a) => bench::run(a),
        Cmd::Crb(a) => crb::run(a),
        Cmd::Convert(a) => convert::run(a),
        Cmd::Recover(a) => recover::run(a),
        Cmd::FakeAutopilot(a) => fake_autopilot::run(a),
    };
    match r {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("lightpose: {}", one_line(&e));
            ExitCode::FAILURE
        }
    }
}

/// One line: the chain of causes joined by ": ", the place named first. A
/// cause whose text the line already holds is left out: the libraries put
/// their cause in their own message, and a stray one that also chains it
/// must not make the line say it twice.
fn one_line(e: &anyhow::Error) -> String {
    let mut line = e.to_string();
    for cause in e.chain().skip(1) {
        let text = cause.to_string();
        if !text.is_empty() && !line.contains(&text) {
            line.push_str(": ");
            line.push_str(&text);
        }
    }
    line.replace(['\n', '\r'], " ")
}

#[cfg(test)]
mod tests {
    use super::one_line;
    use anyhow::Context;

    /// An error that says its cause and also chains it, as a careless
    /// library type might.
    #[derive(Debug)]
    struct Both(std::io::Error);
    impl std::fmt::Display for Both {
        fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
            write!(f, "a.toml: {}", self.0)
        }
    }
    impl std::error::Error for Both {
        fn source(&self) -> Option<&(dyn std::error::Error + 'static)> {
            Some(&self.0)
        }
    }

    #[test]
    fn each_cause_is_said_once() {
        let io = || std::io::Error::new(std::io::ErrorKind::NotFound, "gone");
        let e = anyhow::Error::new(Both(io()));
        assert_eq!(one_line(&e), "a.toml: gone");
        let e = Err::<(), _>(Both(io())).context("loading").unwrap_err();
        assert_eq!(one_line(&e), "loading: a.toml: gone");
        // Causes that say something new are all kept.
        let e = Err::<(), _>(io()).context("replaying x").unwrap_err();
        assert_eq!(one_line(&e), "replaying x: gone");
    }

    /// Every option of every command says what it is in `--help` (an
    /// audit found `sweep --scene`, `--out` and two of fake-autopilot's
    /// with an empty line).
    #[test]
    fn every_option_has_its_help_line() {
        use clap::CommandFactory;
        fn walk(cmd: &clap::Command, path: &str, bare: &mut Vec<String>) {
            for a in cmd.get_arguments() {
                let builtin = matches!(a.get_id().as_str(), "help" | "version");
                if !builtin && a.get_help().is_none() && a.get_long_help().is_none() {
                    bare.push(format!("{path} --{}", a.get_id()));
                }
            }
            for sub in cmd.get_subcommands() {
                if sub.get_about().is_none() && sub.get_name() != "help" {
                    bare.push(format!("{path} {}", sub.get_name()));
                }
                walk(sub, &format!("{path} {}", sub.get_name()), bare);
            }
        }
        let mut bare = Vec::new();
        walk(&super::Cli::command(), "lightpose", &mut bare);
        assert!(bare.is_empty(), "without a help line: {bare:?}");
    }
}
