"""Component dataclasses: parameters and identity of entities, no behaviour."""
