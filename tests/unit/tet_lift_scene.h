// The runner tests' scene: a 1 s tet scene at 10 ms in which the grasper closes at 0.1 s and lifts
// 2 cm by 0.6 s (tetSurface, no gravity). The tests add what they compare (compareAt, nearest).
#pragma once

#include <deform/engine/scene.h>

#include "harness_test_models.h"

namespace deform::testing {

struct TetLiftScene {
  Scene scene;
  Organ organ;
  TetLiftScene() {
    scene.dt = 0.01;
    scene.duration = 1.0;
    scene.gravity = Vec3::Zero();
    ToolSpec t;
    t.radius = 0.005;
    t.trajectory = {KeyFrame{0.0, Vec3(0, 0, 0.1), false}, KeyFrame{0.1, Vec3(0, 0, 0.1), true},
                    KeyFrame{0.6, Vec3(0, 0, 0.12), true}};
    scene.tools.push_back(t);
    organ.source = "test:tet";
    organ.surface = tetSurface();
  }
};

}  // namespace deform::testing
