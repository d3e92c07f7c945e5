"""What the Kirchhoff–Love shell benchmarks share: the shell set-up, plate runs, the
pinched hemisphere."""
