"""LinuxCNC as a test client: its interpreter (rs274) and a headless simulated machine."""
