#include "models/template_cache.h"

#include <link.h>

#include <algorithm>
#include <chrono>
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <sstream>
#include <system_error>
#include <utility>
#include <vector>

#include "models/error.h"
#include "models/fnv1a.h"
#include "models/mesh_export.h"
#include "models/template_generator.h"
#include "models/template_io.h"
#include "models/template_io_internal.h"

namespace artex {
namespace fs = std::filesystem;
namespace {

constexpr char kMagic[8] = {'A', 'R', 'T', 'E', 'X', 'T', 'P', 'L'};
constexpr std::uint32_t kVersion = 1;
// Counts above this are not a template (a damaged header would otherwise ask for terabytes).
constexpr std::uint64_t kMaxCount = 1ull << 28;

class Writer {
 public:
  template <typename T>
  void Put(const T& value) {
    const char* p = reinterpret_cast<const char*>(&value);
    bytes_.append(p, sizeof(T));
  }
  template <typename T>
  void PutArray(const T* data, std::uint64_t count) {
    Put(count);
    const char* p = reinterpret_cast<const char*>(data);
    bytes_.append(p, count * sizeof(T));
  }
  void PutString(const std::string& s) { PutArray(s.data(), s.size()); }
  // An Eigen matrix as rows, then its entries in storage order (column-major).
  template <typename M>
  void PutMatrix(const M& m) {
    Put(static_cast<std::uint64_t>(m.rows()));
    PutArray(m.data(), static_cast<std::uint64_t>(m.size()));
  }
  std::string& bytes() { return bytes_; }

 private:
  std::string bytes_;
};

class Reader {
 public:
  Reader(const std::string& path, const char* data, std::size_t size)
      : path_(path), data_(data), size_(size) {}

  template <typename T>
  T Get(const char* field) {
    T value;
    Need(sizeof(T), field);
    std::memcpy(&value, data_ + at_, sizeof(T));
    at_ += sizeof(T);
    return value;
  }
  template <typename T>
  std::vector<T> GetArray(const char* field) {
    const std::uint64_t count = Count(field);
    Need(count * sizeof(T), field);
    std::vector<T> out(count);
    if (count > 0) std::memcpy(out.data(), data_ + at_, count * sizeof(T));
    at_ += count * sizeof(T);
    return out;
  }
  std::string GetString(const char* field) {
    const std::vector<char> chars = GetArray<char>(field);
    return std::string(chars.begin(), chars.end());
  }
  // A matrix of `cols` columns (fixed by the type) written by Writer::PutMatrix.
  template <typename M>
  void GetMatrix(const char* field, M* m, int cols) {
    const std::uint64_t rows = Count(field);
    const std::uint64_t count = Count(field);
    if (count != rows * static_cast<std::uint64_t>(cols)) {
      Fail(std::string(field) + ": expected " + std::to_string(rows * cols) + " entries (" +
           std::to_string(rows) + " rows x " + std::to_string(cols) + "), found " +
           std::to_string(count));
    }
    Need(count * sizeof(typename M::Scalar), field);
    m->resize(static_cast<Eigen::Index>(rows), cols);
    if (count > 0) std::memcpy(m->data(), data_ + at_, count * sizeof(typename M::Scalar));
    at_ += count * sizeof(typename M::Scalar);
  }
  std::size_t at() const { return at_; }
  [[noreturn]] void Fail(const std::string& what) const {
    throw Error(path_ + ": not a readable artex template cache file: " + what);
  }

 private:
  std::uint64_t Count(const char* field) {
    const std::uint64_t n = Get<std::uint64_t>(field);
    if (n > kMaxCount) {
      Fail(std::string(field) + ": expected a count <= " + std::to_string(kMaxCount) +
           ", found " + std::to_string(n));
    }
    return n;
  }
  void Need(std::uint64_t bytes, const char* field) const {
    if (bytes > size_ - at_) {
      Fail(std::string(field) + ": expected " + std::to_string(bytes) + " more bytes, found " +
           std::to_string(size_ - at_) + " (truncated)");
    }
  }
  std::string path_;
  const char* data_;
  std::size_t size_;
  std::size_t at_ = 0;
};

// The PT_NOTE segments of the loaded object that contains `address`: its NT_GNU_BUILD_ID.
struct BuildIdSearch {
  std::uintptr_t address = 0;
  std::string id;
};

int FindBuildId(dl_phdr_info* info, std::size_t, void* data) {
  auto* search = static_cast<BuildIdSearch*>(data);
  bool contains = false;
  for (int i = 0; i < info->dlpi_phnum && !contains; ++i) {
    const ElfW(Phdr)& ph = info->dlpi_phdr[i];
    if (ph.p_type != PT_LOAD) continue;
    const std::uintptr_t begin = info->dlpi_addr + ph.p_vaddr;
    contains = search->address >= begin && search->address < begin + ph.p_memsz;
  }
  if (!contains) return 0;
  for (int i = 0; i < info->dlpi_phnum; ++i) {
    const ElfW(Phdr)& ph = info->dlpi_phdr[i];
    if (ph.p_type != PT_NOTE) continue;
    const char* p = reinterpret_cast<const char*>(info->dlpi_addr + ph.p_vaddr);
    const char* end = p + ph.p_memsz;
    while (p + sizeof(ElfW(Nhdr)) <= end) {
      ElfW(Nhdr) note;
      std::memcpy(&note, p, sizeof(note));
      const std::size_t name_size = (note.n_namesz + 3) & ~std::size_t{3};
      const std::size_t desc_size = (note.n_descsz + 3) & ~std::size_t{3};
      const char* name = p + sizeof(note);
      const char* desc = name + name_size;
      if (desc + note.n_descsz > end) break;
      if (note.n_type == NT_GNU_BUILD_ID && note.n_namesz == 4 &&
          std::memcmp(name, "GNU", 4) == 0) {
        static const char kHex[] = "0123456789abcdef";
        for (std::size_t k = 0; k < note.n_descsz; ++k) {
          const unsigned char b = static_cast<unsigned char>(desc[k]);
          search->id += kHex[b >> 4];
          search->id += kHex[b & 15];
        }
        return 1;
      }
      p = desc + desc_size;
    }
  }
  return 1;  // the object, without a build ID
}

// "template-<build>.bin"
bool IsCacheFileName(const std::string& name) {
  return name.rfind("template-", 0) == 0 && fs::path(name).extension() == ".bin";
}

// Cached templates of other builds beyond `keep` (this build's included), oldest written first,
// are removed, and temporary files a crashed writer left (older than an hour). Best effort:
// errors are ignored (another process may be doing the same).
void PruneCache(const fs::path& dir, int keep) {
  try {
    std::error_code ec;
    const auto stale = fs::file_time_type::clock::now() - std::chrono::hours(1);
    std::vector<std::pair<fs::file_time_type, fs::path>> files;
    for (const auto& entry : fs::directory_iterator(dir, ec)) {
      const std::string name = entry.path().filename().string();
      const bool cached = IsCacheFileName(name);
      const bool temporary = IsCacheFileName(AtomicWriteTarget(name));  // a writer's
      if (!temporary && !cached) continue;
      std::error_code time_ec;
      const auto time = fs::last_write_time(entry.path(), time_ec);
      if (time_ec) continue;
      if (temporary) {
        if (time < stale) fs::remove(entry.path(), ec);
      } else {
        files.emplace_back(time, entry.path());
      }
    }
    if (static_cast<int>(files.size()) <= keep) return;
    std::sort(files.begin(), files.end());
    for (std::size_t i = 0; i + keep < files.size(); ++i) fs::remove(files[i].second, ec);
  } catch (const std::exception&) {
  }
}

}  // namespace

bool TemplateCacheOptions::IsValid(std::string* error) const {
  if (keep_files >= 1) return true;
  if (error) *error = "template_cache_keep: expected >= 1, found " + std::to_string(keep_files);
  return false;
}

std::string TemplateCacheDirectory(const TemplateCacheOptions& options) {
  if (!options.directory.empty()) return options.directory;
  const auto env = [](const char* name) {
    const char* value = std::getenv(name);
    return value != nullptr ? std::string(value) : std::string();
  };
  if (!env("ARTEX_CACHE_DIR").empty()) return env("ARTEX_CACHE_DIR");
  if (!env("XDG_CACHE_HOME").empty()) return (fs::path(env("XDG_CACHE_HOME")) / "artex").string();
  if (!env("HOME").empty()) return (fs::path(env("HOME")) / ".cache" / "artex").string();
  return "";
}

std::string ProgramBuildId() {
  static const std::string id = [] {
    BuildIdSearch search;
    search.address = reinterpret_cast<std::uintptr_t>(&FindBuildId);
    dl_iterate_phdr(&FindBuildId, &search);
    return search.id;
  }();
  return id;
}

void WriteTemplateBinary(const Template& tmpl, const std::string& path) {
  Writer w;
  w.bytes().append(kMagic, sizeof(kMagic));
  w.Put(kVersion);
  w.PutMatrix(tmpl.vertices);
  w.PutMatrix(tmpl.triangles);
  w.PutMatrix(tmpl.uvs);
  w.PutMatrix(tmpl.uv_triangles);
  w.PutMatrix(tmpl.triangle_chart);
  w.Put(static_cast<std::uint64_t>(tmpl.joints.size()));
  for (const Joint& j : tmpl.joints) {
    w.PutString(j.name);
    w.Put(static_cast<std::int64_t>(j.parent));
    w.PutArray(j.center.data(), 3);
    w.PutArray(j.twist_axis.data(), 3);
  }
  w.PutMatrix(tmpl.vertex_joint);
  w.PutMatrix(tmpl.lbs_weight);
  w.PutMatrix(tmpl.slerp_tau);
  const std::uint64_t checksum = Fnv1a(w.bytes().data(), w.bytes().size());
  w.Put(checksum);

  // A reader sees the old file or the whole new one, never a part.
  WriteFileAtomically(path, w.bytes());
}

Template ReadTemplateBinary(const std::string& path) {
  const std::string bytes = template_io_internal::ReadFileBytes(path);
  Reader r(path, bytes.data(), bytes.size());
  if (bytes.size() < sizeof(kMagic) + sizeof(kVersion) + sizeof(std::uint64_t) ||
      std::memcmp(bytes.data(), kMagic, sizeof(kMagic)) != 0) {
    r.Fail("expected the header ARTEXTPL");
  }
  const std::size_t payload = bytes.size() - sizeof(std::uint64_t);
  std::uint64_t stored;
  std::memcpy(&stored, bytes.data() + payload, sizeof(stored));
  const std::uint64_t computed = Fnv1a(bytes.data(), payload);
  if (stored != computed) {
    std::ostringstream msg;
    msg << "checksum: expected " << std::hex << computed << ", found " << stored;
    r.Fail(msg.str());
  }
  Reader body(path, bytes.data() + sizeof(kMagic), payload - sizeof(kMagic));
  const std::uint32_t version = body.Get<std::uint32_t>("version");
  if (version != kVersion) {
    body.Fail("version: expected " + std::to_string(kVersion) + ", found " +
              std::to_string(version));
  }
  Template t;
  body.GetMatrix("vertices", &t.vertices, 3);
  body.GetMatrix("triangles", &t.triangles, 3);
  body.GetMatrix("uvs", &t.uvs, 2);
  body.GetMatrix("uv_triangles", &t.uv_triangles, 3);
  body.GetMatrix("triangle_chart", &t.triangle_chart, 1);
  const std::uint64_t joints = body.Get<std::uint64_t>("joints");
  if (joints > 4096) body.Fail("joints: expected at most 4096, found " + std::to_string(joints));
  t.joints.resize(joints);
  for (Joint& j : t.joints) {
    j.name = body.GetString("joint name");
    j.parent = static_cast<int>(body.Get<std::int64_t>("joint parent"));
    const std::vector<double> center = body.GetArray<double>("joint center");
    const std::vector<double> axis = body.GetArray<double>("joint twist axis");
    if (center.size() != 3 || axis.size() != 3) body.Fail("joint: expected 3-vectors");
    j.center = Eigen::Vector3d(center[0], center[1], center[2]);
    j.twist_axis = Eigen::Vector3d(axis[0], axis[1], axis[2]);
  }
  body.GetMatrix("vertex_joint", &t.vertex_joint, 1);
  body.GetMatrix("lbs_weight", &t.lbs_weight, 1);
  body.GetMatrix("slerp_tau", &t.slerp_tau, 1);
  if (body.at() != payload - sizeof(kMagic)) {
    body.Fail("expected the checksum after slerp_tau, found " +
              std::to_string(payload - sizeof(kMagic) - body.at()) + " more bytes");
  }
  std::string why;
  if (!t.IsValid(&why)) body.Fail(why);
  return t;
}

Template ReadTemplateFile(const std::string& path) {
  return fs::path(path).extension() == ".bin" ? ReadTemplateBinary(path) : ReadTemplateGlb(path);
}

Template DefaultTemplate(const TemplateCacheOptions& options, std::string* note) {
  if (note) note->clear();
  std::string why;
  if (!options.IsValid(&why)) throw Error("template cache options: " + why);
  const std::string id = ProgramBuildId();
  const std::string dir = TemplateCacheDirectory(options);
  if (!options.enabled || id.empty() || dir.empty()) return GenerateTemplate();
  const fs::path path = fs::path(dir) / ("template-" + id + ".bin");
  std::error_code ec;
  if (fs::exists(path, ec)) {
    try {
      return ReadTemplateBinary(path.string());
    } catch (const Error& e) {
      if (note) *note = std::string(e.what()) + "; generated again and rewritten";
    }
  }
  Template t = GenerateTemplate();
  fs::create_directories(dir, ec);
  try {
    WriteTemplateBinary(t, path.string());
    PruneCache(dir, options.keep_files);
  } catch (const Error& e) {
    if (note) {
      *note += (note->empty() ? "" : "; ") + std::string("the default template's cache: ") +
               e.what() + " (the template is generated at every run)";
    }
  }
  return t;
}

}  // namespace artex
