"""station: end-of-line calibration of MEMS IMUs (accelerometer + gyroscope triads).

The calibration method follows Kolhoff & Kemper, "An Effective Method for Data
Processing of Inertial Measurement Units Applied to Embedded Systems": raw output
``x~ = M x + b_stat + b_drift(t) + noise`` (eq. 1) with a first-order Gauss-Markov
drifting bias (eq. 3) corrected online by Algorithm 1.
"""

__version__ = "0.1.0"
