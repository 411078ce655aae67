"""hsp: hierarchical sensorimotor primitives learned from RGB-D demonstrations.

Implements Liang, Wen, Bekris and Boularias, "Learning Sensorimotor Primitives of
Sequential Manipulation Tasks from Visual Demonstrations" (ICRA 2022).
"""

__version__ = "0.1.0"
