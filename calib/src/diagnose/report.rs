//! Report: plots and a one-page summary.
