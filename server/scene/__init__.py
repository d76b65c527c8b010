"""The viser 3D scene: the only code that talks to viser (DESIGN §3, §8)."""
