#pragma once
// The generated loop of the pipeline tests that reconstruct a whole scene in
// seconds: the tabletop over a quarter loop, 72 frames of 192x108 (1.25 deg apart:
// dense enough for the method, short enough for a test).
#include "synth/sequence.h"

namespace lfrecon::testing {

inline synth::SynthOptions TabletopQuarterLoop() {
  synth::SynthOptions o;
  o.scene = "tabletop";
  o.frames = 72;
  o.loops = 0.25;
  o.width = 192;
  o.height = 108;
  return o;
}

}  // namespace lfrecon::testing
