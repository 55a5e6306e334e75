//! One module per subcommand: options (clap) and a `run` that calls the libraries.

pub mod bake;
pub mod capture;
pub mod demo;
pub mod export;
pub mod inspect;
pub mod light;
pub mod render;
pub mod view;
