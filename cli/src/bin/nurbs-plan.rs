fn main() -> std::process::ExitCode {
    nurbs_motion::panics::install();
    match nurbs_motion::panics::catch(nurbs_cli::run) {
        Ok(code) => code,
        Err(panic) => {
            eprintln!("nurbs-plan: internal error (please report it with the input and the command): {panic}");
            std::process::ExitCode::from(70)
        }
    }
}
