"""State estimation: Kalman filters that turn noisy sensor readings into estimates."""
