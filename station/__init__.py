"""The station's domain: MBS kinematics and error model, the effect vocabulary,
compensation, ISO 230-2 analysis, vision, sequencer, results, discovery; and the CLI."""

__version__ = "0.1.0"
