"""Foreign simulators driven by scbg: harnesses that put one scbg-driven car among a simulator's own."""
