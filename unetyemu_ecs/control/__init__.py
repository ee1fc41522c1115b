"""Pure vectorised laws (control and simple physics models): no esper, no PyBullet."""
