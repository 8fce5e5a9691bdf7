fn main() -> std::process::ExitCode {
    vectorfusion::cli::main()
}
