// Class-name files and model files as untrusted input: a folder, a device such as
// /dev/zero (a path a memory records can name anything) or a file larger than the limit
// is refused by name before anything is read.
#include <vmap/hooks/class_names.hpp>
#include <vmap/hooks/detail/dnn.hpp>
#include <vmap/hooks/xfeat.hpp>

#include "support/errors.hpp"
#include "support/shared_data.hpp"

#include <doctest/doctest.h>

#include <filesystem>
#include <fstream>
#include <string>

TEST_CASE("class names: a folder or a device is an error naming it") {
  const auto dir = vmap::test::scratch_dir("hooks_load_limits");
  CHECK(vmap::test::error_of([&] { (void)vmap::read_class_names(dir); })
            .find("class names file '" + dir.string() + "' is a folder") != std::string::npos);
  CHECK(vmap::test::error_of([] { (void)vmap::read_class_names("/dev/zero"); })
            .find("class names file '/dev/zero' is not a regular file") != std::string::npos);
}

TEST_CASE("model files: a device, a link to one, a folder or a file above 1 GiB is refused by name, unread") {
  const auto dir = vmap::test::scratch_dir("hooks_model_limits");
  std::filesystem::create_symlink("/dev/zero", dir / "zero.onnx");
  {
    // Sparse: one byte more than the limit, without writing a gigabyte.
    std::ofstream(dir / "huge.onnx").close();
    std::filesystem::resize_file(dir / "huge.onnx", vmap::max_model_file_bytes + 1);
  }
  const std::string not_regular = "is not a regular file (a device, FIFO or socket cannot be read as one)";
  for (const std::string& model : {std::string("/dev/zero"), (dir / "zero.onnx").string()}) {
    CAPTURE(model);
    CHECK(vmap::test::error_of([&] { (void)vmap::XFeatDescriptor({.model = model}); }) ==
          "XFeat: model file '" + model + "' " + not_regular);
    CHECK(vmap::test::error_of([&] { (void)vmap::detail::DnnNet(model, "YOLO"); }) ==
          "YOLO: model file '" + model + "' " + not_regular);
  }
  CHECK(vmap::test::error_of([&] { (void)vmap::detail::DnnNet(dir, "YOLO"); }) ==
        "YOLO: model file '" + dir.string() + "' is a folder, expected a file");
  CHECK(vmap::test::error_of([&] { (void)vmap::XFeatDescriptor({.model = dir / "huge.onnx"}); }) ==
        "XFeat: model file '" + (dir / "huge.onnx").string() + "' is 1073741825 bytes, more than the limit of 1073741824");
  CHECK(vmap::test::error_of([&] { (void)vmap::detail::DnnNet(dir / "missing.onnx", "YOLO"); }) ==
        "YOLO: model file '" + (dir / "missing.onnx").string() + "': does not exist");
}
