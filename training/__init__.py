"""PyTorch reference of the Material Picker networks, fixtures and conventions (see README.md)."""
