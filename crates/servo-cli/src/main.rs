fn main() -> std::process::ExitCode {
    servo_cli::main_with_args(std::env::args_os())
}
