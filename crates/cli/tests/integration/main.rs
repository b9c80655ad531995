//! All integration tests, compiled into one test binary.

mod accel;
mod bad_input;
mod bench;
mod common;
mod diff;
mod gltf;
mod images;
mod mitsuba;
mod pbrt;
mod shared_scenes;
