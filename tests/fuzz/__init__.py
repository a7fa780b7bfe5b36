"""The fuzzing tier (docs/testing.md "Fuzzing"): generated and mutated inputs through the CLI."""
