//! `flowlight`: the command-line renderer. The subcommands live in the `flowlight-cli` crate
//! (`crates/cli/src`, one module per subcommand).

fn main() {
    flowlight_cli::main();
}
