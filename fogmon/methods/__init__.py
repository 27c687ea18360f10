"""Methods of the papers behind fogmon, as pure functions on arrays (rate in deg/h,
time in s): thermal-drift calibration and real-time correction (thermal), in-orbit
evaluation by differencing and the Pauta criterion (inorbit), Kalman and wavelet
denoising (denoise), and the up/down Earth-rate calibration (earthrate)."""
