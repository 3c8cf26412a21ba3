"""User data kept across runs: record-and-replay patches."""

from rehabkit.store.patches import Action, Patch, PatchStore, StoreError

__all__ = ["Action", "Patch", "PatchStore", "StoreError"]
