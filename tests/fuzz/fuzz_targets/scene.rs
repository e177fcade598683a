#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    if let Ok(d) = harmonic::scene::exercise(data) {
        assert_eq!(d.non_finite, 0, "a step returned Ok with a non-finite state");
    }
});
