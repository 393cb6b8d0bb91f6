"""The parameter fit: pure numerics (numpy, scipy), sessions in, frozen parameter sets out."""
