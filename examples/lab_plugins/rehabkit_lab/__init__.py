"""Example rehabkit plugins, one of each kind (see pyproject.toml for how each is registered)."""
