fn main() -> std::process::ExitCode {
    quiet_headless_vulkan();
    smocap::cli::main()
}

/// On a headless Linux machine, Mesa's Vulkan drivers (which `--backend auto` probes for a GPU)
/// print "error: XDG_RUNTIME_DIR is invalid or not set in the environment." through libwayland,
/// twice, before any of our output: an error that is none (wgpu always asks for the Wayland
/// surface extension). A runtime directory for the process silences it; set at the start of
/// `main`, before any thread exists to read the environment.
fn quiet_headless_vulkan() {
    let unset = |k: &str| std::env::var_os(k).is_none_or(|v| v.is_empty());
    if cfg!(target_os = "linux") && unset("XDG_RUNTIME_DIR") && unset("WAYLAND_DISPLAY") {
        std::env::set_var("XDG_RUNTIME_DIR", std::env::temp_dir());
    }
}
