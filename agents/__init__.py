"""agents — baselines and Stable-Baselines3 controllers for the rotor environments."""
