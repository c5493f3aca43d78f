//! The benches' command line: `--name VALUE` options read by name with their defaults, and the
//! other words (a bench's file arguments) in order; cargo's own `--bench` is dropped.

use std::str::FromStr;

/// The arguments a bench was started with.
pub struct Flags {
    args: Vec<String>,
    /// The option names read so far: what [`Flags::rest`] leaves out with their values.
    names: std::cell::RefCell<Vec<String>>,
}

impl Flags {
    /// This process's arguments.
    pub fn from_env() -> Flags {
        Flags { args: std::env::args().skip(1).collect(), names: Default::default() }
    }

    /// The value after option `name` (`"--steps"`), if given; panics naming the option when
    /// its value is missing or not a `T`.
    pub fn opt<T: FromStr>(&self, name: &str) -> Option<T> {
        self.names.borrow_mut().push(name.to_string());
        let k = self.args.iter().position(|a| a == name)?;
        let value = self.args.get(k + 1).and_then(|v| v.parse().ok());
        Some(value.unwrap_or_else(|| panic!("{name} takes a value ({})", std::any::type_name::<T>())))
    }

    /// [`Flags::opt`], or `default` when the option is not given.
    pub fn get<T: FromStr>(&self, name: &str, default: T) -> T {
        self.opt(name).unwrap_or(default)
    }

    /// The words that are neither an option read so far nor its value, nor `--bench`.
    pub fn rest(&self) -> Vec<String> {
        let names = self.names.borrow();
        let mut rest = Vec::new();
        let mut words = self.args.iter();
        while let Some(w) = words.next() {
            if names.contains(w) {
                words.next();
            } else if w != "--bench" {
                rest.push(w.clone());
            }
        }
        rest
    }
}
