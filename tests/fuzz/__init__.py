"""The fuzzing tier (README "Fuzzing"): generated and mutated inputs through the CLI."""
