#pragma once

// The vocabulary file formats vmap writes (`vmap vocabulary convert`, the Python module's
// Vocabulary.save): vmap's own, ORB-SLAM2's text (ORBvoc.txt) and FBoW's binary, the
// last two for binary vocabularies only. The format is named, or picked from the file's
// extension: .txt ORB-SLAM2 text, .fbow FBoW, anything else vmap's.

#include <vmap/core/error.hpp>
#include <vmap/place/vocabulary.hpp>
#include <vmap/place/vocabulary_import.hpp>

#include <filesystem>
#include <string>

namespace vmap::examples {

/// "vmap", "orbslam_text" or "fbow" for a file name.
inline std::string vocabulary_format_of(const std::filesystem::path& path) {
  const std::string ext = path.extension().string();
  if (ext == ".txt") return "orbslam_text";
  if (ext == ".fbow") return "fbow";
  return "vmap";
}

/// The bytes of `v` in `format`; `who` names the vocabulary in the error for a float
/// vocabulary written as text or FBoW (those formats hold binary ones).
inline std::string vocabulary_file_bytes(const AnyVocabulary& v, const std::string& format, const std::string& who) {
  if (format == "vmap") return v.serialize();
  if (format != "orbslam_text" && format != "fbow")
    vmap::detail::fail("vocabulary format must be 'vmap', 'orbslam_text' or 'fbow', not '" + format + "'");
  if (v.binary() == nullptr)
    vmap::detail::fail(who + " is a float vocabulary; " + (format == "fbow" ? "FBoW" : "ORB-SLAM2 text") +
                       " files hold binary ones");
  return format == "fbow" ? fbow_bytes(*v.binary()) : orbslam_text(*v.binary());
}

}  // namespace vmap::examples
