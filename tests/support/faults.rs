//! Fault injection for a spawned `kac serve`: the engine reads it from the environment in debug builds only
//! (`kac::service::faults`), never from its flags. The tests ask for it with these two pseudo-flags in their
//! extra arguments, which `split` takes out and turns into the environment.

/// The pseudo-flags `--test-job-delay-ms N` and `--test-panic-analysis NAME` as environment variables; the other
/// arguments as given.
pub fn split<'a>(extra: &[&'a str]) -> (Vec<&'a str>, Vec<(&'static str, &'a str)>) {
    let (mut args, mut env) = (vec![], vec![]);
    let mut it = extra.iter();
    while let Some(&a) = it.next() {
        match a {
            "--test-job-delay-ms" => env.push(("KAC_TEST_JOB_DELAY_MS", *it.next().expect("a delay"))),
            "--test-panic-analysis" => env.push(("KAC_TEST_PANIC_ANALYSIS", *it.next().expect("an analysis"))),
            a => args.push(a),
        }
    }
    (args, env)
}
