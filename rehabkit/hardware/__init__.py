"""Hardware link: the wire protocol between rehabkit and a robot-side bridge."""
