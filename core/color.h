// sRGB transfer functions (IEC 61966-2-1), per channel value. crease keeps images
// linear in memory (DESIGN.md); these convert at file and detector boundaries.
#pragma once

namespace crease {

float SrgbToLinear(float v);
// Clamps to [0, 1] first.
float LinearToSrgb(float v);

}  // namespace crease
