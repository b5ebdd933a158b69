#include "sensors/bvh.h"

#include <algorithm>
#include <cctype>
#include <cerrno>
#include <cmath>
#include <cstdlib>
#include <fstream>
#include <sstream>

#include "models/error.h"
#include "models/file_context.h"
#include "models/numeric.h"
#include "sensors/yaml_checks.h"

namespace artex {
namespace {

// Bones shorter than this (BVH units or metres) have no usable direction.
constexpr double kMinBoneLength = 1e-9;

struct Token {
  std::string text;
  int line = 0;  // 1-based
};

std::vector<std::string> SplitWhitespace(const std::string& line) {
  std::vector<std::string> out;
  std::istringstream ss(line);
  std::string t;
  while (ss >> t) out.push_back(t);
  return out;
}

bool ParseDouble(const std::string& s, double* value) {
  if (s.empty()) return false;
  errno = 0;
  char* end = nullptr;
  *value = std::strtod(s.c_str(), &end);
  return end == s.c_str() + s.size() && errno != ERANGE && std::isfinite(*value);
}

bool ParseInt(const std::string& s, long* value) {
  if (s.empty()) return false;
  errno = 0;
  char* end = nullptr;
  *value = std::strtol(s.c_str(), &end, 10);
  return end == s.c_str() + s.size() && errno != ERANGE;
}

bool ParseChannel(const std::string& s, BvhChannel* channel) {
  static const struct {
    const char* name;
    BvhChannel channel;
  } kNames[] = {{"Xposition", BvhChannel::kXposition}, {"Yposition", BvhChannel::kYposition},
                {"Zposition", BvhChannel::kZposition}, {"Xrotation", BvhChannel::kXrotation},
                {"Yrotation", BvhChannel::kYrotation}, {"Zrotation", BvhChannel::kZrotation}};
  for (const auto& n : kNames) {
    if (s == n.name) {
      *channel = n.channel;
      return true;
    }
  }
  return false;
}

class BvhParser {
 public:
  BvhParser(std::istream& in, const std::string& source) : source_(source) {
    std::string line;
    while (std::getline(in, line)) lines_.push_back(line);
  }

  BvhClip Parse() {
    clip_.source = source_;
    ParseHierarchy();
    ParseMotion();
    return std::move(clip_);
  }

 private:
  [[noreturn]] void Fail(int line, const std::string& message) const {
    throw Error(source_ + ":" + std::to_string(line) + ": " + message);
  }

  // Next hierarchy token, or a failure naming what was expected at the end of the file.
  const Token& Next(const std::string& expected) {
    while (token_index_ >= tokens_.size()) {
      if (next_line_ >= lines_.size()) {
        Fail(static_cast<int>(lines_.size()),
             "unexpected end of file in HIERARCHY, expected " + expected + OpenBlocksDescription());
      }
      tokens_.clear();
      token_index_ = 0;
      for (std::string& t : SplitWhitespace(lines_[next_line_])) {
        tokens_.push_back(Token{t, static_cast<int>(next_line_) + 1});
      }
      ++next_line_;
    }
    return tokens_[token_index_++];
  }

  std::string OpenBlocksDescription() const {
    if (stack_.empty()) return "";
    const OpenBlock& b = stack_.back();
    return " (block of '" + clip_.joints[b.joint].name + "' opened at line " +
           std::to_string(b.line) + " is not closed)";
  }

  double NextNumber(const std::string& what) {
    const Token& t = Next(what);
    double v = 0.0;
    if (!ParseDouble(t.text, &v))
      Fail(t.line, "expected a number for " + what + ", found '" + t.text + "'");
    return v;
  }

  void Expect(const std::string& text) {
    const Token& t = Next("'" + text + "'");
    if (t.text != text) Fail(t.line, "expected '" + text + "', found '" + t.text + "'");
  }

  void OpenJoint(std::string name, int parent, bool end_site) {
    BvhJoint joint;
    joint.name = name;
    joint.parent = parent;
    joint.end_site = end_site;
    joint.first_channel = clip_.num_channels;
    clip_.joints.push_back(joint);
    const Token& brace = Next("'{'");
    if (brace.text != "{")
      Fail(brace.line, "expected '{' after '" + name + "', found '" + brace.text + "'");
    stack_.push_back(OpenBlock{static_cast<int>(clip_.joints.size()) - 1, brace.line, false});
  }

  void ParseHierarchy() {
    Expect("HIERARCHY");
    const Token& root = Next("'ROOT'");
    if (root.text != "ROOT") Fail(root.line, "expected 'ROOT', found '" + root.text + "'");
    OpenJoint(Next("a ROOT name").text, -1, false);
    while (!stack_.empty()) {
      const Token& t = Next("OFFSET, CHANNELS, JOINT, End Site or '}'");
      OpenBlock& block = stack_.back();
      BvhJoint& joint = clip_.joints[block.joint];
      if (t.text == "OFFSET") {
        const int line = t.line;
        if (block.has_offset) Fail(line, "second OFFSET in '" + joint.name + "'");
        for (int a = 0; a < 3; ++a) {
          clip_.joints[block.joint].offset[a] = NextNumber("OFFSET of '" + joint.name + "'");
        }
        stack_.back().has_offset = true;
      } else if (t.text == "CHANNELS") {
        const int line = t.line;
        if (joint.end_site) Fail(line, "CHANNELS inside an End Site");
        if (!joint.channels.empty()) Fail(line, "second CHANNELS in '" + joint.name + "'");
        const Token& count_token = Next("a channel count");
        long count = 0;
        if (!ParseInt(count_token.text, &count) || count < 0 || count > 6) {
          Fail(count_token.line, "CHANNELS of '" + joint.name +
                                     "': expected a count in [0, 6], found '" + count_token.text +
                                     "'");
        }
        std::vector<BvhChannel> channels;
        for (long c = 0; c < count; ++c) {
          const Token& name = Next("a channel name");
          BvhChannel channel;
          if (!ParseChannel(name.text, &channel)) {
            Fail(name.line, "unknown channel '" + name.text + "' in '" + joint.name +
                                "' (expected Xposition, Yposition, Zposition, Xrotation, "
                                "Yrotation or Zrotation)");
          }
          if (std::find(channels.begin(), channels.end(), channel) != channels.end()) {
            Fail(name.line, "duplicate channel '" + name.text + "' in '" + joint.name + "'");
          }
          channels.push_back(channel);
        }
        BvhJoint& j = clip_.joints[stack_.back().joint];
        j.channels = channels;
        j.first_channel = clip_.num_channels;
        clip_.num_channels += static_cast<int>(channels.size());
      } else if (t.text == "JOINT") {
        if (joint.end_site) Fail(t.line, "JOINT inside an End Site");
        const int parent = block.joint;
        OpenJoint(Next("a JOINT name").text, parent, false);
      } else if (t.text == "End") {
        if (joint.end_site) Fail(t.line, "End Site inside an End Site");
        const int parent = block.joint;
        Expect("Site");
        OpenJoint(clip_.joints[parent].name + "/End Site", parent, true);
      } else if (t.text == "}") {
        if (!block.has_offset) Fail(t.line, "'" + joint.name + "' has no OFFSET");
        stack_.pop_back();
      } else {
        Fail(t.line, "unexpected '" + t.text + "' in '" + joint.name +
                         "' (expected OFFSET, CHANNELS, JOINT, End Site or '}')");
      }
    }
    const Token& motion = Next("'MOTION'");
    if (motion.text == "ROOT") Fail(motion.line, "a second ROOT is not supported");
    if (motion.text != "MOTION")
      Fail(motion.line, "expected 'MOTION', found '" + motion.text + "'");
    if (token_index_ < tokens_.size()) {
      Fail(motion.line, "unexpected '" + tokens_[token_index_].text + "' after MOTION");
    }
  }

  // Next non-blank line's tokens (line number in *line); false at the end of the file.
  bool NextLine(std::vector<std::string>* tokens, int* line) {
    while (next_line_ < lines_.size()) {
      *tokens = SplitWhitespace(lines_[next_line_]);
      *line = static_cast<int>(++next_line_);
      if (!tokens->empty()) return true;
    }
    return false;
  }

  void ParseMotion() {
    std::vector<std::string> tokens;
    int line = static_cast<int>(next_line_);
    if (!NextLine(&tokens, &line)) Fail(line, "unexpected end of file, expected 'Frames:'");
    long frames = 0;
    if (tokens.size() != 2 || tokens[0] != "Frames:" || !ParseInt(tokens[1], &frames) ||
        frames < 0) {
      Fail(line, "expected 'Frames: <count >= 0>', found '" + lines_[line - 1] + "'");
    }
    if (!NextLine(&tokens, &line)) Fail(line, "unexpected end of file, expected 'Frame Time:'");
    double frame_time = 0.0;
    if (tokens.size() != 3 || tokens[0] != "Frame" || tokens[1] != "Time:" ||
        !ParseDouble(tokens[2], &frame_time) || !(frame_time > 0.0)) {
      Fail(line, "expected 'Frame Time: <seconds > 0>', found '" + lines_[line - 1] + "'");
    }
    if (frame_time < kBvhMinFrameTime || frame_time > kBvhMaxFrameTime) {
      std::ostringstream range;
      range << "expected a Frame Time in [" << kBvhMinFrameTime << ", " << kBvhMaxFrameTime
            << "] s, found " << tokens[2];
      Fail(line, range.str());
    }
    clip_.frame_time = frame_time;
    const size_t remaining_lines = lines_.size() - next_line_;
    // One line per frame (blank without channels): the count is capped by the file's size.
    if (static_cast<size_t>(frames) > remaining_lines) {
      Fail(static_cast<int>(lines_.size()), "truncated: 'Frames: " + std::to_string(frames) +
                                                "' but only " + std::to_string(remaining_lines) +
                                                " lines follow");
    }
    clip_.values.resize(frames, clip_.num_channels);
    for (long f = 0; f < frames; ++f) {
      if (clip_.num_channels == 0) break;  // frame lines are blank
      if (!NextLine(&tokens, &line)) {
        Fail(line, "truncated: 'Frames: " + std::to_string(frames) + "' but only " +
                       std::to_string(f) + " frame lines");
      }
      if (static_cast<int>(tokens.size()) != clip_.num_channels) {
        Fail(line, "frame " + std::to_string(f) + ": expected " +
                       std::to_string(clip_.num_channels) + " values (one per channel), found " +
                       std::to_string(tokens.size()));
      }
      for (int c = 0; c < clip_.num_channels; ++c) {
        double v = 0.0;
        if (!ParseDouble(tokens[c], &v)) {
          Fail(line, "frame " + std::to_string(f) + ", value " + std::to_string(c + 1) +
                         ": expected a finite number, found '" + tokens[c] + "'");
        }
        clip_.values(f, c) = v;
      }
    }
    if (NextLine(&tokens, &line)) {
      Fail(line, "more frame lines than 'Frames: " + std::to_string(frames) + "'");
    }
  }

  struct OpenBlock {
    int joint;
    int line;
    bool has_offset;
  };

  std::string source_;
  std::vector<std::string> lines_;
  size_t next_line_ = 0;
  std::vector<Token> tokens_;
  size_t token_index_ = 0;
  std::vector<OpenBlock> stack_;
  BvhClip clip_;
};

// ---------------------------------------------------------------------------------------
// Retargeting.

std::string NormalizeName(const std::string& name) {
  const size_t colon = name.find_last_of(':');
  std::string s = colon == std::string::npos ? name : name.substr(colon + 1);
  for (char& c : s) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return s;
}

struct NameCandidates {
  const char* joint;
  std::vector<const char*> bvh_names;  // normalised, in priority order
};

// CMU "Hips/LowerBack/Spine1/LeftArm" (31 joints), "hip/abdomen/chest/lShldr" (43 joints),
// "Hips/Chest/CS_BVH/LeftShoulder" (19 joints) and Mixamo-like names.
const std::vector<NameCandidates>& NameTable() {
  static const std::vector<NameCandidates> kTable = {
      {"pelvis", {"hips", "hip", "pelvis", "root"}},
      {"spine", {"lowerback", "abdomen", "spine", "chest"}},
      {"chest", {"spine2", "spine1", "chest", "cs_bvh", "upperback", "thorax"}},
      {"neck", {"neck", "neck1", "lowerneck"}},
      {"head", {"head"}},
      {"l_shoulder", {"leftarm", "lshldr", "leftuparm", "leftshoulder"}},
      {"l_elbow", {"leftforearm", "lforearm", "leftelbow", "leftlowarm"}},
      {"l_wrist", {"lefthand", "lhand", "leftwrist"}},
      {"r_shoulder", {"rightarm", "rshldr", "rightuparm", "rightshoulder"}},
      {"r_elbow", {"rightforearm", "rforearm", "rightelbow", "rightlowarm"}},
      {"r_wrist", {"righthand", "rhand", "rightwrist"}},
      {"l_hip", {"leftupleg", "lthigh", "lefthip", "leftupperleg"}},
      {"l_knee", {"leftleg", "lshin", "leftknee", "leftlowleg", "leftlowerleg"}},
      {"l_ankle", {"leftfoot", "lfoot", "leftankle"}},
      {"r_hip", {"rightupleg", "rthigh", "righthip", "rightupperleg"}},
      {"r_knee", {"rightleg", "rshin", "rightknee", "rightlowleg", "rightlowerleg"}},
      {"r_ankle", {"rightfoot", "rfoot", "rightankle"}},
  };
  return kTable;
}

// Pre-order entry and exit numbers of every joint: `joint` is a proper descendant of
// `ancestor` iff enter[ancestor] < enter[joint] < exit[ancestor]. Linear time (a walk to the root
// per query made retargeting quadratic on a 100,000-joint chain, issue 20).
struct JointIntervals {
  std::vector<int> enter, exit;
  bool IsDescendant(int joint, int ancestor) const {
    return enter[ancestor] < enter[joint] && enter[joint] < exit[ancestor];
  }
};

JointIntervals ComputeJointIntervals(const BvhClip& clip) {
  const int n = static_cast<int>(clip.joints.size());
  std::vector<std::vector<int>> children(n);
  std::vector<int> roots;
  for (int j = 0; j < n; ++j) {
    const int p = clip.joints[j].parent;
    (p >= 0 && p < n ? children[p] : roots).push_back(j);
  }
  JointIntervals t;
  t.enter.assign(n, -1);
  t.exit.assign(n, -1);
  int clock = 0;
  std::vector<std::pair<int, size_t>> stack;  // (joint, next child)
  for (int r : roots) {
    t.enter[r] = clock++;
    stack.push_back({r, 0});
    while (!stack.empty()) {
      auto& [j, next] = stack.back();
      if (next < children[j].size()) {
        const int c = children[j][next++];
        t.enter[c] = clock++;
        stack.push_back({c, 0});
      } else {
        t.exit[j] = clock++;
        stack.pop_back();
      }
    }
  }
  return t;
}

Eigen::Matrix3d MinimalRotation(const Eigen::Vector3d& from, const Eigen::Vector3d& to) {
  return Eigen::Quaterniond::FromTwoVectors(from, to).toRotationMatrix();
}

}  // namespace

int BvhClip::FindJoint(const std::string& name) const {
  for (int j = 0; j < static_cast<int>(joints.size()); ++j) {
    if (joints[j].name == name) return j;
  }
  return -1;
}

std::vector<int> BvhClip::Children(int joint) const {
  std::vector<int> children;
  for (int j = 0; j < static_cast<int>(joints.size()); ++j) {
    if (joints[j].parent == joint) children.push_back(j);
  }
  return children;
}

BvhClip ParseBvh(std::istream& in, const std::string& source) {
  BvhParser parser(in, source);
  return parser.Parse();
}

BvhClip ReadBvh(const std::string& path) {
  CheckNotAFolder(path, "a BVH file");
  std::ifstream in(path);
  if (!in) throw Error(path + ": cannot open BVH file");
  return WithFileContext(path, [&] { return ParseBvh(in, path); });
}

BvhFrame BvhRestFrame(const BvhClip& clip) {
  BvhFrame frame;
  frame.rotations.assign(clip.joints.size(), Eigen::Quaterniond::Identity());
  for (const BvhJoint& j : clip.joints) frame.translations.push_back(j.offset);
  return frame;
}

BvhFrame BvhFrameAt(const BvhClip& clip, int f) {
  if (f < 0 || f >= clip.num_frames()) {
    throw Error(clip.source + ": frame " + std::to_string(f) + " out of range [0, " +
                std::to_string(clip.num_frames()) + ")");
  }
  BvhFrame frame = BvhRestFrame(clip);
  for (size_t j = 0; j < clip.joints.size(); ++j) {
    const BvhJoint& joint = clip.joints[j];
    Eigen::Quaterniond q = Eigen::Quaterniond::Identity();
    for (size_t c = 0; c < joint.channels.size(); ++c) {
      const double v = clip.values(f, joint.first_channel + static_cast<int>(c));
      switch (joint.channels[c]) {
        case BvhChannel::kXposition:
          frame.translations[j].x() = v;
          break;
        case BvhChannel::kYposition:
          frame.translations[j].y() = v;
          break;
        case BvhChannel::kZposition:
          frame.translations[j].z() = v;
          break;
        case BvhChannel::kXrotation:
          q = q * Eigen::AngleAxisd(v * kDegToRad, Eigen::Vector3d::UnitX());
          break;
        case BvhChannel::kYrotation:
          q = q * Eigen::AngleAxisd(v * kDegToRad, Eigen::Vector3d::UnitY());
          break;
        case BvhChannel::kZrotation:
          q = q * Eigen::AngleAxisd(v * kDegToRad, Eigen::Vector3d::UnitZ());
          break;
      }
    }
    frame.rotations[j] = q.normalized();
  }
  return frame;
}

BvhFrame SampleBvh(const BvhClip& clip, double time_s) {
  if (clip.num_frames() == 0) throw Error(clip.source + ": the clip has no frames");
  const double x = std::clamp(time_s, 0.0, clip.duration()) / clip.frame_time;
  const int i = std::min(static_cast<int>(std::floor(x)), clip.num_frames() - 1);
  const double w = x - i;
  if (i == clip.num_frames() - 1 || w <= 0.0) return BvhFrameAt(clip, i);
  BvhFrame a = BvhFrameAt(clip, i);
  const BvhFrame b = BvhFrameAt(clip, i + 1);
  for (size_t j = 0; j < a.rotations.size(); ++j) {
    a.rotations[j] = a.rotations[j].slerp(w, b.rotations[j]);
    a.translations[j] = (1.0 - w) * a.translations[j] + w * b.translations[j];
  }
  return a;
}

int ResampledFrameCount(const BvhClip& clip, double frame_rate, double tolerance) {
  if (clip.num_frames() == 0) return 0;
  const double count = std::floor(clip.duration() * frame_rate + tolerance) + 1;
  if (!(count <= kBvhMaxResampledFrames)) {
    std::ostringstream msg;
    msg << clip.source << ": resampling " << clip.duration() << " s at " << frame_rate
        << " Hz: expected at most " << kBvhMaxResampledFrames << " frames, found " << count;
    throw Error(msg.str());
  }
  return static_cast<int>(count);
}

int CountLeadingJumpFrames(const BvhClip& clip, double max_deg_per_s) {
  const double max_step = max_deg_per_s * kDegToRad * clip.frame_time;
  int n = 0;
  if (clip.num_frames() < 2) return 0;
  BvhFrame prev = BvhFrameAt(clip, 0);
  for (int f = 0; f + 1 < clip.num_frames(); ++f) {
    const BvhFrame next = BvhFrameAt(clip, f + 1);
    double step = 0.0;
    for (size_t j = 0; j < next.rotations.size(); ++j) {
      step = std::max(step, prev.rotations[j].angularDistance(next.rotations[j]));
    }
    if (step <= max_step) break;
    n = f + 1;
    prev = next;
  }
  return n;
}

std::vector<BvhFrame> ResampleBvh(const BvhClip& clip, double frame_rate, double tolerance) {
  if (!(frame_rate > 0.0)) throw Error("BVH resampling: frame_rate must be > 0");
  std::vector<BvhFrame> frames;
  const int n = ResampledFrameCount(clip, frame_rate, tolerance);
  frames.reserve(n);
  for (int k = 0; k < n; ++k) frames.push_back(SampleBvh(clip, k / frame_rate));
  return frames;
}

void BvhForwardKinematics(const BvhClip& clip, const BvhFrame& frame,
                          std::vector<Eigen::Matrix3d>* rotations, Eigen::MatrixX3d* positions) {
  const int n = static_cast<int>(clip.joints.size());
  rotations->resize(n);
  positions->resize(n, 3);
  for (int j = 0; j < n; ++j) {
    const int p = clip.joints[j].parent;
    const Eigen::Matrix3d local = frame.rotations[j].toRotationMatrix();
    if (p < 0) {
      (*rotations)[j] = local;
      positions->row(j) = frame.translations[j].transpose();
    } else {
      (*rotations)[j] = (*rotations)[p] * local;
      positions->row(j) = positions->row(p) + ((*rotations)[p] * frame.translations[j]).transpose();
    }
  }
}

bool BvhRetargetOptions::IsValid(std::string* error) const {
  std::ostringstream msg;
  const double orthonormality =
      (bvh_to_template * bvh_to_template.transpose() - Eigen::Matrix3d::Identity()).norm();
  if (!(frame_rate > 0.0) || !std::isfinite(frame_rate)) {
    msg << "bvh.frame_rate: expected > 0 Hz, found " << frame_rate;
  } else if (skip_frames < -1) {
    msg << "bvh.skip_frames: expected >= 0 or -1 (automatic), found " << skip_frames;
  } else if (!(leading_jump_deg_per_s > 0.0)) {
    msg << "bvh.leading_jump_deg_per_s: expected > 0, found " << leading_jump_deg_per_s;
  } else if (!(resample_tolerance >= 0.0 && resample_tolerance < 0.5)) {
    msg << "bvh.resample_tolerance: expected in [0, 0.5), found " << resample_tolerance;
  } else if (!(translation_scale >= 0.0) || !std::isfinite(translation_scale)) {
    msg << "bvh.translation_scale: expected >= 0 (0 = automatic), found " << translation_scale;
  } else if (!(orthonormality < 1e-6) || !(bvh_to_template.determinant() > 0.0)) {
    msg << "bvh.bvh_to_template: expected a rotation matrix, found deviation from "
           "orthonormality "
        << orthonormality << " and determinant " << bvh_to_template.determinant();
  } else {
    return true;
  }
  if (error != nullptr) *error = msg.str();
  return false;
}

std::vector<int> MapBvhJoints(const BvhClip& clip, const Template& tmpl,
                              const BvhRetargetOptions& options) {
  if (clip.joints.empty()) throw Error(clip.source + ": BVH has no joints");
  const int num_joints = tmpl.num_joints();
  std::vector<int> map(num_joints, -1);
  std::vector<bool> used(clip.joints.size(), false);
  const JointIntervals intervals = ComputeJointIntervals(clip);
  std::vector<std::string> normalized(clip.joints.size());
  for (size_t j = 0; j < clip.joints.size(); ++j)
    normalized[j] = NormalizeName(clip.joints[j].name);
  for (int k = 0; k < num_joints; ++k) {
    const std::string& name = tmpl.joints[k].name;
    int ancestor = -1;  // BVH joint of the nearest mapped template ancestor
    for (int a = tmpl.joints[k].parent; a >= 0 && ancestor < 0; a = tmpl.joints[a].parent) {
      ancestor = map[a];
    }
    auto admissible = [&](int j) {
      return !clip.joints[j].end_site && !used[j] &&
             (ancestor < 0 || intervals.IsDescendant(j, ancestor));
    };
    const auto override_it = std::find_if(options.joint_map.begin(), options.joint_map.end(),
                                          [&](const auto& entry) { return entry.first == name; });
    int chosen = -1;
    if (override_it != options.joint_map.end()) {
      if (!override_it->second.empty()) {
        chosen = clip.FindJoint(override_it->second);
        if (chosen < 0) {
          throw Error(clip.source + ": bvh.joint_map: template joint '" + name +
                      "' maps to BVH joint '" + override_it->second + "', which does not exist");
        }
        if (!admissible(chosen)) {
          throw Error(clip.source + ": bvh.joint_map: BVH joint '" + override_it->second +
                      "' for template joint '" + name +
                      "' is an End Site, already used, or not below the BVH joint of the "
                      "template joint's mapped ancestor");
        }
      }
    } else {
      std::vector<std::string> candidates;
      for (const NameCandidates& entry : NameTable()) {
        if (name == entry.joint) candidates.assign(entry.bvh_names.begin(), entry.bvh_names.end());
      }
      const std::string own = NormalizeName(name);
      if (std::find(candidates.begin(), candidates.end(), own) == candidates.end()) {
        candidates.push_back(own);
      }
      for (const std::string& candidate : candidates) {
        for (int j = 0; j < static_cast<int>(clip.joints.size()) && chosen < 0; ++j) {
          if (normalized[j] == candidate && admissible(j)) chosen = j;
        }
        if (chosen >= 0) break;
      }
      if (k == 0 && chosen < 0) chosen = 0;
    }
    map[k] = chosen;
    if (chosen >= 0) used[chosen] = true;
  }
  if (map[0] < 0) throw Error(clip.source + ": bvh.joint_map leaves the template root unmapped");
  return map;
}

std::vector<Pose> RetargetBvh(const BvhClip& full_clip, const Template& tmpl,
                              const BvhRetargetOptions& options) {
  std::string error;
  if (!options.IsValid(&error)) throw Error(error);
  if (full_clip.num_frames() == 0) throw Error(full_clip.source + ": the clip has no frames");
  const int skip = options.skip_frames >= 0
                       ? options.skip_frames
                       : CountLeadingJumpFrames(full_clip, options.leading_jump_deg_per_s);
  if (skip >= full_clip.num_frames()) {
    throw Error(full_clip.source + ": bvh.skip_frames = " + std::to_string(skip) +
                " leaves no frame of " + std::to_string(full_clip.num_frames()));
  }
  BvhClip trimmed;
  if (skip > 0) {
    trimmed.source = full_clip.source;
    trimmed.joints = full_clip.joints;
    trimmed.num_channels = full_clip.num_channels;
    trimmed.frame_time = full_clip.frame_time;
    trimmed.values = full_clip.values.bottomRows(full_clip.num_frames() - skip);
  }
  const BvhClip& clip = skip > 0 ? trimmed : full_clip;
  if (tmpl.num_joints() == 0) throw Error("RetargetBvh: the template has no joints");
  const std::vector<int> map = MapBvhJoints(clip, tmpl, options);
  const int num_joints = tmpl.num_joints();
  const Eigen::Matrix3d& w = options.bvh_to_template;

  // Rest pose of the BVH in template axes.
  std::vector<Eigen::Matrix3d> rest_rot;
  Eigen::MatrixX3d rest_pos;
  BvhForwardKinematics(clip, BvhRestFrame(clip), &rest_rot, &rest_pos);
  rest_pos = (rest_pos * w.transpose()).eval();

  // Main mapped child of each template joint: the mapped child whose template bone is most
  // aligned with the joint's twist axis and whose bones have a length in both skeletons.
  std::vector<int> main_child(num_joints, -1);
  for (int c = 1; c < num_joints; ++c) {
    const int k = tmpl.joints[c].parent;
    if (k < 0 || map[k] < 0 || map[c] < 0) continue;
    const Eigen::Vector3d bone = tmpl.joints[c].center - tmpl.joints[k].center;
    const Eigen::Vector3d bvh_bone = (rest_pos.row(map[c]) - rest_pos.row(map[k])).transpose();
    if (bone.norm() < kMinBoneLength || bvh_bone.norm() < kMinBoneLength) continue;
    const Eigen::Vector3d& axis = tmpl.joints[k].twist_axis;
    if (main_child[k] < 0 ||
        bone.normalized().dot(axis) >
            (tmpl.joints[main_child[k]].center - tmpl.joints[k].center).normalized().dot(axis)) {
      main_child[k] = c;
    }
  }
  // Rest alignment A_k (template bone direction -> BVH rest bone direction); leaves and
  // unmapped joints inherit their parent's.
  std::vector<Eigen::Matrix3d> align(num_joints, Eigen::Matrix3d::Identity());
  std::vector<Eigen::Vector3d> bvh_rest_dir(num_joints, Eigen::Vector3d::Zero());
  for (int k = 0; k < num_joints; ++k) {
    const int p = tmpl.joints[k].parent;
    if (p >= 0) align[k] = align[p];
    if (p < 0 || map[k] < 0 || main_child[k] < 0) continue;
    const int c = main_child[k];
    bvh_rest_dir[k] = (rest_pos.row(map[c]) - rest_pos.row(map[k])).transpose().normalized();
    align[k] = MinimalRotation((tmpl.joints[c].center - tmpl.joints[k].center).normalized(),
                               bvh_rest_dir[k]);
  }

  // Translation scale (metres per BVH unit).
  const int root = map[0];
  double scale = options.translation_scale;
  if (scale == 0.0) {
    const double tmpl_low = tmpl.num_vertices() > 0 ? tmpl.vertices.col(1).minCoeff() : [&] {
      double m = tmpl.joints[0].center.y();
      for (const Joint& j : tmpl.joints) m = std::min(m, j.center.y());
      return m;
    }();
    const double tmpl_height = tmpl.joints[0].center.y() - tmpl_low;
    const double bvh_height = rest_pos(root, 1) - rest_pos.col(1).minCoeff();
    if (!(tmpl_height > kMinBoneLength) || !(bvh_height > kMinBoneLength)) {
      throw Error(clip.source + ": cannot derive the translation scale (template pelvis height " +
                  std::to_string(tmpl_height) + " m, BVH rest root height " +
                  std::to_string(bvh_height) + "); set bvh.translation_scale");
    }
    scale = tmpl_height / bvh_height;
  }

  const std::vector<BvhFrame> frames =
      ResampleBvh(clip, options.frame_rate, options.resample_tolerance);
  std::vector<Pose> poses;
  poses.reserve(frames.size());
  std::vector<Eigen::Matrix3d> rot;
  Eigen::MatrixX3d pos;
  std::vector<Eigen::Matrix3d> q(num_joints);
  const Eigen::Vector3d pelvis = tmpl.joints[0].center;
  for (const BvhFrame& frame : frames) {
    BvhForwardKinematics(clip, frame, &rot, &pos);
    for (int k = 0; k < num_joints; ++k) {
      const int p = tmpl.joints[k].parent;
      if (map[k] < 0) {
        q[k] = p < 0 ? Eigen::Matrix3d::Identity() : q[p];
        continue;
      }
      const Eigen::Matrix3d g = w * rot[map[k]] * w.transpose();
      if (p < 0) {
        q[k] = g;
      } else if (main_child[k] >= 0) {
        const Eigen::Vector3d dir = w * (pos.row(map[main_child[k]]) - pos.row(map[k])).transpose();
        const Eigen::Matrix3d correction =
            dir.norm() > kMinBoneLength ? MinimalRotation(g * bvh_rest_dir[k], dir.normalized())
                                        : Eigen::Matrix3d::Identity();
        q[k] = correction * g * align[k];
      } else {
        q[k] = g * align[k];
      }
    }
    Pose pose = Pose::Identity(num_joints);
    pose.rotation = q[0];
    for (int k = 1; k < num_joints; ++k) {
      pose.joint_rotations[k] = q[tmpl.joints[k].parent].transpose() * q[k];
    }
    const Eigen::Vector3d root_position = scale * (w * pos.row(root).transpose());
    pose.translation = root_position - pose.rotation * pelvis;
    poses.push_back(pose);
  }
  if (options.center_first_frame) {
    Eigen::Vector3d shift = pelvis - (poses[0].rotation * pelvis + poses[0].translation);
    shift.y() = 0.0;
    for (Pose& pose : poses) pose.translation += shift;
  }
  PlaceOnFloor(tmpl, options.floor, &poses);
  return poses;
}

std::vector<Pose> LoadBvhMotion(const std::string& path, const Template& tmpl,
                                const BvhRetargetOptions& options) {
  return RetargetBvh(ReadBvh(path), tmpl, options);
}

}  // namespace artex
