// Each ErrorKind raised by its real cause: a program tells "start a new memory" (a
// missing file) from "keep the damaged one aside" (corrupt), "upgrade vmap" (a newer
// format), "fix the configuration" (other policies, a bad option), "wait" (another
// writer) and "free the disk" (io) by the kind, not by the message.

#include "support/sample_memory.hpp"
#include "support/shared_data.hpp"

#include <vmap/core/error.hpp>
#include <vmap/core/names.hpp>
#include <vmap/geometry/fundamental.hpp>
#include <vmap/io/atomic_file.hpp>
#include <vmap/io/files.hpp>
#include <vmap/keyframe/map_io.hpp>
#include <vmap/memory/records.hpp>
#include <vmap/memory/stacks.hpp>
#include <vmap/memory/store.hpp>
#include <vmap/memory/visual_memory.hpp>

#include <doctest/doctest.h>

#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include <csignal>
#include <filesystem>
#include <optional>
#include <string>

namespace {

using vmap::test::read_bytes;
using vmap::test::write_bytes;

namespace fs = std::filesystem;
using vmap::ErrorKind;

/// `name` in this file's scratch folder, with nothing there (vmap::test::fresh_path).
std::filesystem::path kinds_path(const std::string& name) { return vmap::test::fresh_path("error_kinds", name); }

/// The kind of the vmap::Error `action` throws; nullopt when it throws none.
std::optional<ErrorKind> kind_of(auto&& action) {
  try {
    action();
  } catch (const vmap::Error& e) {
    return e.kind();
  }
  return std::nullopt;
}

/// A small memory of the sample frames, saved at `path`.
void save_small_memory(const fs::path& path) {
  auto memory = vmap::test::make_small_memory(vmap::test::small_memory_options());
  for (std::size_t i = 0; i < 12; ++i) memory.push(vmap::test::sample_frames()[i]);
  memory.save(path);
}

vmap::OrbVisualMemory load(const fs::path& path, vmap::OrbDescriptor descriptor = vmap::OrbDescriptor{}) {
  return vmap::OrbVisualMemory::load(path, descriptor, vmap::BruteForceMatcher{}, vmap::test::memory_estimator(),
                                     vmap::InlierRatio{});
}

}  // namespace

TEST_CASE("error kinds: names both ways; a plain Error is an invalid argument and still a runtime_error") {
  for (ErrorKind k : {ErrorKind::invalid_argument, ErrorKind::not_found, ErrorKind::corrupt,
                      ErrorKind::unsupported_version, ErrorKind::policy_mismatch, ErrorKind::busy, ErrorKind::io,
                      ErrorKind::unavailable}) {
    CAPTURE(to_string(k));
    CHECK(to_string(k) != "unknown");
    CHECK(vmap::from_string<ErrorKind>(to_string(k)) == k);
  }
  CHECK(vmap::from_string<ErrorKind>("missing") == std::nullopt);
  CHECK(vmap::Error("x").kind() == ErrorKind::invalid_argument);
  const vmap::Error e(ErrorKind::busy, "held");
  CHECK(e.kind() == ErrorKind::busy);
  CHECK(std::string(e.what()) == "held");
  CHECK_THROWS_AS(vmap::detail::check(false, ErrorKind::io, "disk"), std::runtime_error);
  CHECK(kind_of([] { vmap::detail::check(false, ErrorKind::corrupt, [] { return std::string("lazy"); }); }) ==
        ErrorKind::corrupt);
  CHECK(kind_of([] { vmap::detail::check(true, ErrorKind::corrupt, "holds"); }) == std::nullopt);
}

TEST_CASE("error kinds: a bad option is invalid_argument") {
  CHECK(kind_of([] { (void)vmap::parse<vmap::RobustMethod>("magsak", "--estimator"); }) == ErrorKind::invalid_argument);
  CHECK(kind_of([] { (void)vmap::test::make_small_memory({.vocabulary_after = 0}); }) == ErrorKind::invalid_argument);
}

TEST_CASE("error kinds: a file or folder that does not exist is not_found") {
  const fs::path missing = kinds_path("missing.vmem");
  CHECK(kind_of([&] { (void)vmap::read_file(missing); }) == ErrorKind::not_found);
  CHECK(kind_of([&] { (void)load(missing); }) == ErrorKind::not_found);
  CHECK(kind_of([&] { (void)vmap::load_map(kinds_path("missing.vmap")); }) == ErrorKind::not_found);
  CHECK(kind_of([&] { (void)vmap::MemoryStore::open(kinds_path("missing.vmdb")); }) == ErrorKind::not_found);
  CHECK(kind_of([&] { vmap::write_file_atomically(kinds_path("no-folder") / "x.txt", "x"); }) == ErrorKind::not_found);
}

TEST_CASE("error kinds: a damaged memory, map or store is corrupt; a newer format is unsupported_version") {
  const fs::path good = kinds_path("good.vmem");
  save_small_memory(good);
  const std::string bytes = read_bytes(good);
  REQUIRE(bytes.size() > 64);

  SUBCASE("truncated") {
    const fs::path p = kinds_path("truncated.vmem");
    write_bytes(p, bytes.substr(0, bytes.size() / 2));
    CHECK(kind_of([&] { (void)load(p); }) == ErrorKind::corrupt);
  }
  SUBCASE("garbage") {
    const fs::path p = kinds_path("garbage.vmem");
    write_bytes(p, std::string(200, 'x'));
    CHECK(kind_of([&] { (void)load(p); }) == ErrorKind::corrupt);
    const fs::path m = kinds_path("garbage.vmap");
    write_bytes(m, std::string(200, 'x'));
    CHECK(kind_of([&] { (void)vmap::load_map(m); }) == ErrorKind::corrupt);
  }
  SUBCASE("a flipped byte in a section") {
    const fs::path p = kinds_path("flipped.vmem");
    std::string b = bytes;
    b[b.size() - 5] = static_cast<char>(b[b.size() - 5] ^ 0x5a);
    write_bytes(p, b);
    CHECK(kind_of([&] { (void)load(p); }) == ErrorKind::corrupt);
  }
  SUBCASE("a format version this build does not read yet") {
    // The header: u8[8] magic, then the u32 version (little-endian).
    const fs::path p = kinds_path("newer.vmem");
    std::string b = bytes;
    b[8] = static_cast<char>(vmap::memory_format_version + 1);
    write_bytes(p, b);
    CHECK(kind_of([&] { (void)load(p); }) == ErrorKind::unsupported_version);
    // Version 0 was never written: damage, not a newer file.
    b[8] = 0;
    write_bytes(p, b);
    CHECK(kind_of([&] { (void)load(p); }) == ErrorKind::corrupt);
  }
  SUBCASE("a file that is not an SQLite database, opened as a store") {
    const fs::path p = kinds_path("not-sqlite.vmdb");
    write_bytes(p, std::string(4096, 'x'));
    CHECK(kind_of([&] { (void)vmap::MemoryStore::open(p, vmap::sqlite::Access::read); }) == ErrorKind::corrupt);
  }
}

TEST_CASE("error kinds: a memory loaded or merged with other policies is policy_mismatch") {
  const fs::path p = kinds_path("orb.vmem");
  save_small_memory(p);
  CHECK(kind_of([&] { (void)load(p, vmap::OrbDescriptor({.features = 123})); }) == ErrorKind::policy_mismatch);
  auto into = load(p);
  auto other = vmap::test::make_small_memory(vmap::test::small_memory_options(vmap::ImageStorage::png));
  for (std::size_t i = 0; i < 3; ++i) other.push(vmap::test::sample_frames()[i]);
  CHECK(kind_of([&] { into.merge(std::move(other)); }) == ErrorKind::policy_mismatch);
}

TEST_CASE("error kinds: a store another program writes is busy") {
  const fs::path p = kinds_path("busy.vmdb");
  auto writer = vmap::MemoryStore::create(p);
  CHECK(kind_of([&] { (void)vmap::MemoryStore::open(p); }) == ErrorKind::busy);
  CHECK(kind_of([&] { (void)vmap::sqlite::WriterLock(p, false, "memory"); }) == ErrorKind::busy);
}

TEST_CASE("error kinds: a write the system refuses (a full disk) is io") {
  // A file size limit of 0 (ulimit -f 0, SIGXFSZ ignored) makes every write fail with
  // EFBIG, as a full disk does with ENOSPC; it is set in a child, which reports the kind
  // by its exit code, so that this process keeps its limits.
  const fs::path p = kinds_path("full.txt");
  const pid_t child = ::fork();
  REQUIRE(child >= 0);
  if (child == 0) {
    std::signal(SIGXFSZ, SIG_IGN);
    const rlimit none{0, 0};
    ::setrlimit(RLIMIT_FSIZE, &none);
    const auto k = kind_of([&] { vmap::write_file_atomically(p, std::string(4096, 'x')); });
    ::_exit(k == ErrorKind::io ? 0 : k ? 10 + static_cast<int>(*k) : 9);
  }
  int status = 0;
  REQUIRE(::waitpid(child, &status, 0) == child);
  REQUIRE(WIFEXITED(status));
  CHECK(WEXITSTATUS(status) == 0);
  CHECK_FALSE(fs::exists(p));
}
