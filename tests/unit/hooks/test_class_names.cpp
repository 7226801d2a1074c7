#include <vmap/hooks/class_names.hpp>

#include "support/shared_data.hpp"

#include <doctest/doctest.h>

#include <filesystem>
#include <fstream>
#include <string>

namespace {
std::filesystem::path write(const std::filesystem::path& dir, const std::string& name, const std::string& text) {
  const auto p = dir / name;
  std::ofstream(p, std::ios::binary) << text;
  return p;
}
}  // namespace

TEST_CASE("class names: one a line, CRLF and trailing blank lines tolerated") {
  const auto dir = vmap::test::scratch_dir("hooks_names");
  const auto names = vmap::read_class_names(write(dir, "a.names", "person\r\nbicycle \n\ncar\n\n\n"));
  REQUIRE(names.size() == 4);
  CHECK(names[0] == "person");
  CHECK(names[1] == "bicycle");
  CHECK(names[2].empty());
  CHECK(names[3] == "car");
  CHECK(vmap::class_name(names, 3) == "car");
  CHECK(vmap::class_name(names, 2) == "class 2");  // empty line: no name
  CHECK(vmap::class_name(names, 80) == "class 80");
  CHECK(vmap::class_name(names, -1) == "class -1");
}

TEST_CASE("class names: missing, empty and oversized files are errors naming the file") {
  const auto dir = vmap::test::scratch_dir("hooks_names_bad");
  const auto check_error = [](const std::filesystem::path& p, const std::string& part) {
    try {
      (void)vmap::read_class_names(p);
      FAIL("no error for " << p);
    } catch (const vmap::Error& e) {
      const std::string what = e.what();
      CHECK(what.find(p.filename().string()) != std::string::npos);
      CHECK(what.find(part) != std::string::npos);
    }
  };
  check_error(dir / "missing.names", "does not exist");
  check_error(write(dir, "empty.names", "\n \n"), "no class name");
  check_error(write(dir, "huge.names", std::string((1u << 20) + 1, 'x')), "limit");
}

TEST_CASE("coco80.names has the 80 COCO classes in detector order" * doctest::test_suite("data")) {
  const auto names = vmap::read_class_names(vmap::test::model_path("coco80.names"));
  REQUIRE(names.size() == 80);
  CHECK(names[0] == "person");
  CHECK(names[56] == "chair");
  CHECK(names[41] == "cup");
  CHECK(names[79] == "toothbrush");
}
