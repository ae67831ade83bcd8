#pragma once
// The named test scenes of the synthetic generator, each with the camera rig
// it is meant to be seen from. All are in metres with the table top (where
// there is one) at z = 0 and world up +z; the foreground box V lies strictly
// above z = 0 so the table is background.
//
//  tabletop      figurine-like: textured sphere, box, open cup, a stool on thin legs, thin sticks
//                and wires 1-3 px wide (some textureless), textured table, walls and clutter outside V
//  sphere        one textured sphere in front of a textured floor and dome
//  plane         a large textured rectangle, seen fronto-parallel-ish over a 60-degree arc
//  thin_cylinder a textureless vertical cylinder 2-3 px wide in front of a textured background
//  occlusion     textured objects occluding one another around a central pillar
#include <cstdint>
#include <string>
#include <vector>

#include "synth/camera_path.h"
#include "synth/scene.h"

namespace lfrecon::synth {

struct SceneSetup {
  Scene scene;
  CameraPathOptions path;  // the suggested rig (a circle; callers change type and frame count)
};

// The names MakeNamedScene accepts, default first.
const std::vector<std::string>& SceneNames();
// The geometry is fixed per name; `seed` shifts the solid textures so
// different seeds give different images. Throws OptionError listing the names
// for an unknown name.
SceneSetup MakeNamedScene(const std::string& name, std::uint64_t seed = 1);

// Shifts every primitive's noise field by a seeded random offset.
void RandomizeTextureOffsets(Scene* scene, std::uint64_t seed);

}  // namespace lfrecon::synth
