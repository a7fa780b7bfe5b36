"""Feedrate planning (design §2): key points, S-curves, bidirectional scan, time law."""
