#pragma once
// Ground-truth meshes of a synthetic scene: each primitive tessellated with
// its vertices exactly on the analytic surface (to float precision), outward
// normals, and vertex colours from its material. The chord error of curved
// parts is at most `tolerance` metres.
#include "geometry/triangle_mesh.h"
#include "synth/scene.h"

namespace lfrecon::synth {

// Infinite planes cannot be tessellated: they give an empty mesh.
TriangleMesh TessellatePrimitive(const Primitive& primitive, double tolerance = 5e-5);

// All foreground primitives (gt_mesh.ply), or only the foreground ones that
// are thin (gt_thin.ply).
TriangleMesh GroundTruthMesh(const Scene& scene, bool thin_only = false, double tolerance = 5e-5);

}  // namespace lfrecon::synth
