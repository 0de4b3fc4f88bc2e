//! One module per subcommand: its arguments (with units in the help) and its thin driver.

pub mod emulate;
pub mod facets;
pub mod ndf;
pub mod run;
pub mod simulate;
pub mod stream;
pub mod toolpath;
