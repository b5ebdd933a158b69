// The default template, generated once per build and kept on disk (docs/template.md, "The
// default template's cache").
//
// GenerateTemplate() with its defaults costs about half a second (iso-surface, remeshing, UV
// atlas), paid by every `artex track`, `artex overlay` and experiment run that is given no
// template file. Its result depends only on the program's code, so the first such run of a
// build writes it to the cache folder, in a binary file that keeps every double bit for bit
// (a .glb rounds positions to floats), named by the build's GNU build ID; later runs read it
// back (a few milliseconds). A file of another build is never read: a changed generator links
// into a new build ID. A damaged or unreadable file is regenerated and rewritten, a folder that
// cannot be written leaves the template generated and a note saying why.
#pragma once

#include <string>

#include "models/template.h"

namespace artex {

struct TemplateCacheOptions {
  bool enabled = true;  // pipeline.template_cache; false: generate every time
  // pipeline.template_cache_dir; empty: $ARTEX_CACHE_DIR, else $XDG_CACHE_HOME/artex, else
  // $HOME/.cache/artex (none of them set: no cache).
  std::string directory;
  // pipeline.template_cache_keep: cached templates kept in the folder, this build's included
  // (other builds' least recently written are removed beyond this; each is about 1.4 MB).
  int keep_files = 8;

  bool IsValid(std::string* error) const;
};

// The cache folder the options name ("" when none can be found).
std::string TemplateCacheDirectory(const TemplateCacheOptions& options);

// The GNU build ID (hex) of the binary this code is linked into; "" when it has none.
std::string ProgramBuildId();

// GenerateTemplate() bit for bit: read from the cache when this build wrote it there, else
// generated (and written when the cache is enabled). `note`, when given, says what happened
// where it is worth telling (a damaged file replaced, a folder that cannot be written); empty
// otherwise.
Template DefaultTemplate(const TemplateCacheOptions& options = TemplateCacheOptions(),
                         std::string* note = nullptr);

// The binary template file: every field of Template, doubles and ints as stored, with a
// checksum. Write replaces `path` atomically (WriteFileAtomically, models/mesh_export.h); Read
// throws Error naming the file and the field that does not match.
void WriteTemplateBinary(const Template& tmpl, const std::string& path);
Template ReadTemplateBinary(const std::string& path);

// A template file by its extension: .bin as ReadTemplateBinary, anything else as a .glb
// (ReadTemplateGlb). What `--template` and an experiment's runs read.
Template ReadTemplateFile(const std::string& path);

}  // namespace artex
