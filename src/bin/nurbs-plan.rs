fn main() -> std::process::ExitCode {
    nurbs_motion::cli::run()
}
