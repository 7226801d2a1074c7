#include <vmap/hooks/detail/onnx_shape.hpp>

#include "support/protobuf_bytes.hpp"
#include "support/shared_data.hpp"

#include <doctest/doctest.h>

#include <cstdint>
#include <fstream>
#include <iterator>
#include <string>
#include <vector>

namespace {

using vmap::test::field_bytes;
using vmap::test::field_varint;

// ModelProto{ir_version: 7, graph: {node: <junk>, input: {name: "input", type: {tensor_type:
// {elem_type: 1, shape: {dim: 1, dim: 3, dim: "H", dim: 320}}}}}}
std::string model_bytes() {
  const std::string shape = field_bytes(1, field_varint(1, 1)) + field_bytes(1, field_varint(1, 3)) +
                            field_bytes(1, field_bytes(2, "H")) + field_bytes(1, field_varint(1, 320));
  const std::string tensor = field_varint(1, 1) + field_bytes(2, shape);
  const std::string value_info = field_bytes(1, "input") + field_bytes(2, field_bytes(1, tensor));
  const std::string graph = field_bytes(1, std::string(40, '\x01')) + field_bytes(11, value_info) +
                            field_bytes(11, field_bytes(1, "second"));
  return field_varint(1, 7) + field_bytes(7, graph);
}

}  // namespace

TEST_CASE("ONNX first input shape from hand-made protobuf bytes") {
  const auto dims = vmap::detail::onnx_first_input_shape(model_bytes());
  CHECK(dims == std::vector<std::int64_t>{1, 3, -1, 320});
}

TEST_CASE("ONNX shape reader: truncated or garbage bytes give 'unknown', never a crash") {
  const std::string full = model_bytes();
  for (std::size_t n = 0; n < full.size(); ++n)
    CHECK(vmap::detail::onnx_first_input_shape(full.substr(0, n)).empty());
  std::string garbage(4096, '\0');
  cv::RNG rng(11);
  for (auto& c : garbage) c = static_cast<char>(rng.uniform(0, 256));
  (void)vmap::detail::onnx_first_input_shape(garbage);  // must just return
  CHECK(vmap::detail::onnx_first_input_shape(std::string(100, '\xff')).empty());  // endless varint
}

TEST_CASE("ONNX shape reader on the XFeat exports" * doctest::test_suite("data")) {
  for (const auto& [file, want] : {std::pair{"xfeat_320x224.onnx", std::vector<std::int64_t>{1, 3, 224, 320}},
                                   std::pair{"xfeat_256x256.onnx", std::vector<std::int64_t>{1, 3, 256, 256}}}) {
    std::ifstream in(vmap::test::model_path(file), std::ios::binary);
    const std::string bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    CHECK(vmap::detail::onnx_first_input_shape(bytes) == want);
  }
}
