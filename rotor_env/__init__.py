"""rotor_env — the accelerating rotor: effects, simulator, Gymnasium environments, CLI."""
