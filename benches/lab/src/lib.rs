//! # harmonic-lab
//!
//! The measuring apparatus of `harmonic`, kept out of the engine a game embeds: speed against
//! error ([`accuracy`]), the hard-case stability suite ([`stability`]), static equilibria
//! ([`statics`]), step throughput ([`throughput`]), rapier 0.36's soft-body cloth as a peer
//! ([`peer`]), the GPU bench (`gpu_bench`) and a bit-for-bit record of the engine's results for
//! refactors that must change nothing ([`baseline`]) with the frame times beside it
//! ([`frame_time`]). The `harmonic-lab` binary runs them; the figures
//! they write are in `BENCHMARKS.md` and `STABILITY.md` beside this crate.
//!
//! It uses the engine through its public API and, where it needs the packed buffers and the
//! kernels themselves, through `harmonic::internals`.

// A harness over scenes it generates itself: a failure there is a bug in the harness.
#![allow(clippy::expect_used, clippy::unwrap_used)]

pub mod accuracy;
pub mod baseline;
pub mod crossings;
pub mod frame_time;
pub mod game_cost;
#[cfg(feature = "gpu")]
pub mod gpu_bench;
pub mod peer;
pub mod research;
pub mod stability;
pub mod statics;
pub mod throughput;
