//! All integration tests in one binary (faster to build and run than one binary per
//! file). Each module holds the tests of one capability.
mod formfactor;
