// Vocabulary inputs and outputs bounded: gzipped DBoW2 YAML gets the nesting checks of
// plain YAML after it is decompressed, and is decompressed only up to a limit counted
// as the bytes come (not the size its trailer claims); a vocabulary is written only
// where it replaces nothing but another vocabulary, never its own input.

#include <vmap/io/yaml_limits.hpp>
#include <vmap/place/vocabulary.hpp>
#include <vmap/runtime/vocabulary.hpp>

#include "place_support.hpp"
#include "support/fifo.hpp"
#include "support/peak_memory.hpp"

#include <doctest/doctest.h>
#include <sys/stat.h>
#include <zlib.h>

#include <chrono>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <string>

namespace {

namespace fs = std::filesystem;
using vmap::test::error_of;

/// `text` as gzip writes it (one member).
std::string gzip(const std::string& text) {
  z_stream z{};
  REQUIRE(deflateInit2(&z, Z_BEST_COMPRESSION, Z_DEFLATED, 15 + 16, 8, Z_DEFAULT_STRATEGY) == Z_OK);
  std::string out(deflateBound(&z, static_cast<uLong>(text.size())), '\0');
  z.next_in = reinterpret_cast<Bytef*>(const_cast<char*>(text.data()));
  z.avail_in = static_cast<uInt>(text.size());
  z.next_out = reinterpret_cast<Bytef*>(out.data());
  z.avail_out = static_cast<uInt>(out.size());
  REQUIRE(deflate(&z, Z_FINISH) == Z_STREAM_END);
  out.resize(z.total_out);
  deflateEnd(&z);
  return out;
}

void write(const fs::path& p, const std::string& bytes) { std::ofstream(p, std::ios::binary) << bytes; }

std::string bytes_of(const fs::path& p) {
  std::ifstream in(p, std::ios::binary);
  return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

const fs::path& dir() {
  static const fs::path d = vmap::test::scratch_dir("vocabulary_bounds");
  return d;
}

/// "a: [[[[...]]]]" (or "{a: [[[...]]]}") nested `depth` brackets deep.
std::string nested(std::size_t depth, bool in_map) {
  const std::string inner = std::string(depth, '[') + std::string(depth, ']');
  return in_map ? "%YAML:1.0\n{a: " + inner + "}\n" : "%YAML:1.0\na: " + inner + "\n";
}

}  // namespace

TEST_CASE("yaml_depth counts flow brackets, also when they open on one line of a map") {
  CHECK(vmap::yaml_depth("a: 1\n") == 1);
  CHECK(vmap::yaml_depth("a: [1, 2]\n") == 2);
  CHECK(vmap::yaml_depth("a: [[[1]]]\n") == 4);
  CHECK(vmap::yaml_depth("{a: [[1]]}\n") == 4);
  CHECK(vmap::yaml_depth("a: [\n  [\n    [1]]]\n") == 4);  // brackets open across lines, under the key
  CHECK(vmap::yaml_depth("a:\n  b: [\n [1]]\nc: 1\n") == 4);
  CHECK(vmap::yaml_depth("a: \"[[[[\"\n") == 1);           // quoted: not nesting
  CHECK(vmap::yaml_depth(nested(200000, false)) == 200001);
}

TEST_CASE("a gzipped DBoW2 vocabulary nested 200000 brackets deep is refused as the plain one is, not parsed") {
  for (const bool in_map : {false, true}) {
    CAPTURE(in_map);
    const std::string text = nested(200000, in_map);
    const fs::path plain = dir() / (in_map ? "deep_map.yml" : "deep.yml");
    const fs::path gz = dir() / (in_map ? "deep_map.yml.gz" : "deep.yml.gz");
    write(plain, text);
    write(gz, gzip(text));
    CHECK(fs::file_size(gz) < 4096);  // a small file: the text is what is large
    for (const fs::path& p : {plain, gz}) {
      CAPTURE(p);
      const std::string e = error_of([&] { (void)vmap::AnyVocabulary::load(p); });
      // the key's level, the map's brace if any, the 200000 brackets
      const std::string depth = in_map ? "200002" : "200001";
      CHECK(e == "DBoW2 YAML vocabulary '" + p.string() + "': YAML nested " + depth + " levels deep, more than the 16 accepted");
    }
  }
}

TEST_CASE("gzip is decompressed up to the limit counted as it comes, whatever its trailer claims") {
  const std::string text(3 << 20, ' ');
  std::string gz = gzip(text);
  CHECK(vmap::detail::gunzip_bounded(gz, 3 << 20, "src") == text);
  CHECK(error_of([&] { (void)vmap::detail::gunzip_bounded(gz, 1 << 20, "src"); }) ==
        "src: decompresses to more than 1048576 bytes (the limit)");
  // ISIZE (the last 4 bytes) claims 10 bytes: the count stops at the limit all the same.
  gz[gz.size() - 4] = 10;
  gz[gz.size() - 3] = gz[gz.size() - 2] = gz[gz.size() - 1] = 0;
  CHECK(error_of([&] { (void)vmap::detail::gunzip_bounded(gz, 1 << 20, "src"); }) ==
        "src: decompresses to more than 1048576 bytes (the limit)");
  // Within the limit, the wrong size is found by zlib's own check of the trailer.
  CHECK(error_of([&] { (void)vmap::detail::gunzip_bounded(gz, 4 << 20, "src"); }).find("not valid gzip data") !=
        std::string::npos);
  // Cut short, and not gzip at all.
  CHECK(error_of([&] { (void)vmap::detail::gunzip_bounded(gz.substr(0, gz.size() / 2), 4 << 20, "src"); }) ==
        "src: the gzip data is truncated");
  CHECK(error_of([&] { (void)vmap::import_dbow2_yaml_gz(std::string(100, 'x'), "x.yml.gz"); })
            .find("DBoW2 YAML vocabulary 'x.yml.gz': not valid gzip data") == 0);
}

TEST_CASE("a gzipped vocabulary is inflated only as far as its compressed bytes can hold a vocabulary's text") {
  // 40 MiB of YAML filler in 40 kB of gzip: refused at 16 MiB (32 times 40 kB is below
  // the 16 MiB every file may reach), before OpenCV parses anything; the peak memory of
  // the refusal stays near the 16 MiB, not the 40 MiB the file would inflate to.
  const std::string text = "%YAML:1.0\n---\nvocabulary:\n   k: 10\n   x: \"" + std::string(40 << 20, ' ') + "\"\n";
  const fs::path gz = dir() / "filler.yml.gz";
  write(gz, gzip(text));
  const auto compressed = fs::file_size(gz);
  CHECK(compressed < 64000);
  std::string e;
  const auto growth = vmap::test::peak_growth([&] { e = error_of([&] { (void)vmap::AnyVocabulary::load(gz); }); });
  CHECK(e == "DBoW2 YAML vocabulary '" + gz.string() + "': decompresses to more than 16777216 bytes (the limit for " +
                 std::to_string(compressed) + " compressed bytes: 32 times them, at least 16 MiB; gzip shrinks a "
                 "vocabulary's text far less)");
  if (growth) CHECK(*growth < (std::uint64_t{40} << 20));
  // A larger file: the bound is 32 times its bytes (here 1 MiB of gzip, 32 MiB).
  std::string big = gzip(text);
  big.resize(std::size_t{1} << 20, '\0');  // trailing bytes past the member: never reached
  CHECK(error_of([&] { (void)vmap::import_dbow2_yaml_gz(big, "big.yml.gz"); }) ==
        "DBoW2 YAML vocabulary 'big.yml.gz': decompresses to more than 33554432 bytes (the limit for 1048576 compressed "
        "bytes: 32 times them, at least 16 MiB; gzip shrinks a vocabulary's text far less)");
}

TEST_CASE("vocabulary and place database files that are FIFOs or devices are refused before they are opened") {
  const fs::path fifo = vmap::test::make_fifo(dir() / "voc_fifo");
  const vmap::test::FifoWatchdog watchdog({fifo}, std::chrono::seconds(20));  // a hang fails the checks below
  const std::string not_regular = "' is not a regular file (a device, FIFO or socket cannot be read as one)";
  CHECK(error_of([&] { (void)vmap::AnyVocabulary::load(fifo); }) == "vocabulary file '" + fifo.string() + not_regular);
  CHECK(error_of([&] { (void)vmap::BinaryVocabularyTree::load(fifo); }) == "vocabulary file '" + fifo.string() + not_regular);
  CHECK(error_of([&] { (void)vmap::import_binary_vocabulary(fifo); }) == "vocabulary file '" + fifo.string() + not_regular);
  CHECK(error_of([&] { (void)vmap::PlaceDatabase<std::uint32_t>::load(fifo); }) ==
        "place database file '" + fifo.string() + not_regular);
  CHECK(error_of([&] { (void)vmap::PlaceDatabase<std::uint32_t>::load("/dev/zero"); }) ==
        "place database file '/dev/zero" + not_regular);
  CHECK(error_of([&] { (void)vmap::AnyVocabulary::load(dir() / "missing.voc"); }) ==
        "vocabulary file '" + (dir() / "missing.voc").string() + "': does not exist");
}

TEST_CASE("check_vocabulary_output: only a new file, or with overwrite another vocabulary, never the input") {
  const auto data = vmap::test::binary_clusters(4, 3, 10, 7);
  const auto v = vmap::AnyVocabulary::learn(data.images, {.branching = 3, .depth = 2, .seed = 1});
  const fs::path voc = dir() / "voc.bin";
  const fs::path other = dir() / "other.fbow";
  const fs::path memory = dir() / "memory.vmdb";
  const fs::path text = dir() / "notes.txt";
  v.save(voc);
  vmap::save_vocabulary(v, other);
  write(memory, std::string("SQLite format 3") + '\0' + std::string(200, 'm'));
  write(text, "12 my notes\n");
  const std::string memory_bytes = bytes_of(memory);

  // New files are fine.
  CHECK_NOTHROW(vmap::check_vocabulary_output(dir() / "new.bin", false, voc));
  // The input itself: under its own name, another spelling and a link, even with overwrite.
  fs::remove(dir() / "link.bin");
  fs::create_symlink(voc, dir() / "link.bin");
  for (const fs::path& out : {voc, dir() / "." / "voc.bin", dir() / "link.bin"}) {
    CAPTURE(out);
    CHECK(error_of([&] { vmap::check_vocabulary_output(out, true, voc); }) ==
          "vocabulary output '" + out.string() + "' is the input file '" + voc.string() +
              "'; write the vocabulary to another file");
  }
  // An existing vocabulary: only with overwrite.
  CHECK(error_of([&] { vmap::check_vocabulary_output(other, false, voc, "--force"); }) ==
        "vocabulary output '" + other.string() +
            "' already exists; it is replaced only when asked to (--force), and only when it is a vocabulary");
  CHECK_NOTHROW(vmap::check_vocabulary_output(other, true, voc));
  // Anything else, never; by content, not by name.
  for (const fs::path& out : {memory, text}) {
    CAPTURE(out);
    const std::string e = error_of([&] { vmap::check_vocabulary_output(out, true, voc); });
    CHECK(e.find("vocabulary output '" + out.string() + "' exists and is not a vocabulary vmap reads, so it is not replaced") ==
          0);
  }
  CHECK(bytes_of(memory) == memory_bytes);
  // A folder, a device and a FIFO: refused without being opened.
  CHECK(error_of([&] { vmap::check_vocabulary_output(dir(), true, voc); }) ==
        "vocabulary output '" + dir().string() + "' is a folder, expected a file");
  CHECK(error_of([&] { vmap::check_vocabulary_output("/dev/null", true, voc); }) ==
        "vocabulary output '/dev/null' is not a regular file (a device, FIFO or socket); it is not written to");
  const fs::path fifo = dir() / "fifo";
  fs::remove(fifo);
  REQUIRE(::mkfifo(fifo.c_str(), 0600) == 0);
  CHECK(error_of([&] { vmap::check_vocabulary_output(fifo, true, voc); }) ==
        "vocabulary output '" + fifo.string() + "' is not a regular file (a device, FIFO or socket); it is not written to");
}
