"""The sequencer: a run engine with explicit states, and plans as generators of small steps."""
