//! Command-line options of the rendering examples.

use std::path::PathBuf;

/// The flags of the rendering examples.
#[derive(Clone, Debug)]
pub struct Options {
    /// `--lights N`: number of point lights.
    pub lights: usize,
    /// `--width W`: image width in pixels.
    pub width: u32,
    /// `--height H`: image height in pixels.
    pub height: u32,
    /// `--threshold T`: relative threshold of the tree's certified bound.
    pub threshold: f64,
    /// `--out DIR`: where the PNG images go.
    pub out: PathBuf,
}

/// Default relative threshold of the certified bound (1%).
pub const DEFAULT_THRESHOLD: f64 = 0.01;

impl Options {
    /// Parses the process arguments over the defaults `lights` and
    /// `width x height`, [`DEFAULT_THRESHOLD`] and `out/`; prints the usage
    /// and exits on a malformed or unknown flag.
    pub fn parse(lights: usize, size: (u32, u32)) -> Options {
        Self::parse_from(lights, size, std::env::args().skip(1))
    }

    /// [`parse`](Self::parse) over the arguments `args` (without the
    /// program's name), for an example that takes flags of its own out
    /// first.
    pub fn parse_from(
        lights: usize,
        (width, height): (u32, u32),
        args: impl IntoIterator<Item = String>,
    ) -> Options {
        let mut options = Options {
            lights,
            width,
            height,
            threshold: DEFAULT_THRESHOLD,
            out: PathBuf::from("out"),
        };
        let mut args = args.into_iter();
        while let Some(flag) = args.next() {
            let value = args.next().unwrap_or_default();
            let ok = match flag.as_str() {
                "--lights" => value.parse().map(|v| options.lights = v).is_ok(),
                "--width" => value.parse().map(|v| options.width = v).is_ok(),
                "--height" => value.parse().map(|v| options.height = v).is_ok(),
                "--threshold" => value.parse().map(|v| options.threshold = v).is_ok(),
                "--out" => {
                    options.out = PathBuf::from(&value);
                    !value.is_empty()
                }
                _ => false,
            };
            if !ok || options.width == 0 || options.height == 0 || options.threshold < 0.0 {
                eprintln!(
                    "bad argument `{flag} {value}`\n\
                     usage: [--lights N] [--width W] [--height H] [--threshold T] [--out DIR]"
                );
                std::process::exit(2);
            }
        }
        options
    }

    /// Image width and height.
    pub fn size(&self) -> (u32, u32) {
        (self.width, self.height)
    }
}
