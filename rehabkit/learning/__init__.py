"""The learning layer's scenario section (``learning:``): what a policy does, sees and is paid; the environment
that runs it is :mod:`rehabkit.gym`. A package of its own so that every scenario load can validate the section
without importing Gymnasium."""
