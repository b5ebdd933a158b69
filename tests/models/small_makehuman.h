// Test data: a tiny MakeHuman-like folder (models/makehuman_import.h), shared by the tests
// and the fuzz seeds (fuzz/make_seeds.cc).
#pragma once

#include <sstream>
#include <string>

namespace artex::test_data {

struct SmallMakeHuman {
  std::string obj, rig, weights;  // base.obj, mpfb_rig.cmu_mb.json, mpfb_weights.cmu_mb.json
};

// A MakeHuman-like folder's files, small enough for tests and fuzzing (the real base.obj is
// 1.7 MB): a closed box in group "body", a joint cube for the hips, a rig of the 17 bones that
// MakeHumanImportOptions maps plus one finger that merges into its hand (heads from default
// positions, the hips' from its cube, the neck's from two vertices), and weights for every box
// vertex. ImportMakeHuman makes a valid 8-vertex, 17-joint template of it.
inline SmallMakeHuman MakeSmallMakeHuman() {
  std::ostringstream obj;
  obj << "# box body\n";
  for (int i = 0; i < 8; ++i) {
    obj << "v " << ((i & 1) ? 2 : -2) << " " << ((i & 2) ? 17 : 0) << " " << ((i & 4) ? 1 : -1)
        << "\n";
  }
  obj << "vt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\n";
  obj << "g body\n";
  const int quads[6][4] = {{1, 3, 4, 2}, {5, 6, 8, 7}, {1, 2, 6, 5},
                           {3, 7, 8, 4}, {1, 5, 7, 3}, {2, 4, 8, 6}};
  for (const auto& q : quads) {
    obj << "f " << q[0] << "/1 " << q[1] << "/2 " << q[2] << "/3 " << q[3] << "/4\n";
  }
  obj << "v -0.1 9 -0.1\nv 0.1 9 -0.1\nv 0 9.1 0.1\ng joint-hips\nf 9 10 11\n";
  // bone, parent, head and tail (Blender frame: z up, metres).
  const struct {
    const char* name;
    const char* parent;
    double head[3], tail[3];
  } bones[] = {{"Hips", "", {0, 0, 0.9}, {0, 0, 1.0}},
               {"LowerBack", "Hips", {0, 0, 1.0}, {0, 0, 1.2}},
               {"Spine1", "LowerBack", {0, 0, 1.2}, {0, 0, 1.4}},
               {"Neck", "Spine1", {0, 0, 1.45}, {0, 0, 1.55}},
               {"Head", "Neck", {0, 0, 1.55}, {0, 0, 1.7}},
               {"LeftArm", "Spine1", {0.18, 0, 1.4}, {0.45, 0, 1.4}},
               {"LeftForeArm", "LeftArm", {0.45, 0, 1.4}, {0.7, 0, 1.4}},
               {"LeftHand", "LeftForeArm", {0.7, 0, 1.4}, {0.8, 0, 1.4}},
               {"LeftHandFinger1", "LeftHand", {0.8, 0, 1.4}, {0.85, 0, 1.4}},
               {"RightArm", "Spine1", {-0.18, 0, 1.4}, {-0.45, 0, 1.4}},
               {"RightForeArm", "RightArm", {-0.45, 0, 1.4}, {-0.7, 0, 1.4}},
               {"RightHand", "RightForeArm", {-0.7, 0, 1.4}, {-0.8, 0, 1.4}},
               {"LeftUpLeg", "Hips", {0.1, 0, 0.9}, {0.1, 0, 0.5}},
               {"LeftLeg", "LeftUpLeg", {0.1, 0, 0.5}, {0.1, 0, 0.1}},
               {"LeftFoot", "LeftLeg", {0.1, 0, 0.1}, {0.1, -0.1, 0.0}},
               {"RightUpLeg", "Hips", {-0.1, 0, 0.9}, {-0.1, 0, 0.5}},
               {"RightLeg", "RightUpLeg", {-0.1, 0, 0.5}, {-0.1, 0, 0.1}},
               {"RightFoot", "RightLeg", {-0.1, 0, 0.1}, {-0.1, -0.1, 0.0}}};
  std::ostringstream rig, weights;
  rig << "{";
  weights << "{\"name\": \"seed\", \"weights\": {";
  bool first = true;
  for (const auto& b : bones) {
    const auto point = [](const double* p) {
      std::ostringstream s;
      s << "{\"default_position\": [" << p[0] << ", " << p[1] << ", " << p[2]
        << "], \"strategy\": \"DEFAULT\"}";
      return s.str();
    };
    // The hips' head from its joint cube, the neck's from two vertices (MEAN), the rest from
    // default positions.
    std::string head = point(b.head);
    if (std::string(b.name) == "Hips") {
      head = "{\"cube_name\": \"joint-hips\", \"strategy\": \"CUBE\", "
             "\"default_position\": [0, 0, 0.9]}";
    } else if (std::string(b.name) == "Neck") {
      head = "{\"strategy\": \"MEAN\", \"vertex_indices\": [2, 7], "
             "\"default_position\": [0, 0, 1.45]}";
    }
    rig << (first ? "" : ", ") << "\"" << b.name << "\": {\"head\": " << head
        << ", \"tail\": " << point(b.tail) << ", \"parent\": \"" << b.parent
        << "\", \"roll\": 0.0}";
    first = false;
  }
  rig << "}";
  weights << "\"Hips\": [[0, 1.0], [1, 1.0], [4, 0.5], [5, 0.5]], "
          << "\"Head\": [[2, 1.0], [3, 1.0], [6, 0.5], [7, 0.5], [8, 1.0]], "
          << "\"LeftHandFinger1\": [[4, 0.5], [5, 0.5]], \"RightFoot\": [[6, 0.5], [7, 0.5]]}}";
  return {obj.str(), rig.str(), weights.str()};
}

}  // namespace artex::test_data
