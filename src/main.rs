fn main() -> std::process::ExitCode {
    smocap::cli::main()
}
