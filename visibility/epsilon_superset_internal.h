#pragma once
// What the two halves of the ε-superset share (epsilon_superset_setup.cpp builds the prisms
// and Embree's scene, epsilon_superset.cpp answers queries): Embree's device and scene.
// Internal, included by those two files only.

#include <embree3/rtcore.h>

#include "visibility/epsilon_superset.h"

namespace vistream::visibility {

struct EpsilonSuperset::Embree {
  RTCDevice device = nullptr;
  RTCScene scene = nullptr;
  ~Embree() {
    if (scene != nullptr) rtcReleaseScene(scene);
    if (device != nullptr) rtcReleaseDevice(device);
  }
};

}  // namespace vistream::visibility
