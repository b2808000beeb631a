"""Physical constants shared by every part of addb."""

from __future__ import annotations

#: Standard gravity, m/s²: OpenSim's default model gravity, (0, -GRAVITY, 0) in its Y-up
#: ground frame; also the g of body weight (BW = mass x GRAVITY).
GRAVITY = 9.80665

#: The gravity vector in OpenSim's ground frame (Y up), m/s².
GRAVITY_VECTOR = (0.0, -GRAVITY, 0.0)
