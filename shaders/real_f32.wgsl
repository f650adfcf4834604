// The scalar type of shaders/batch.wgsl: f32 (the default), with the built-in sin and cos.
alias real = f32;

fn sn(x: real) -> real {
    return sin(x);
}

fn cs(x: real) -> real {
    return cos(x);
}
