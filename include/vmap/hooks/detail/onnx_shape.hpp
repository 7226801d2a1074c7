#pragma once

// The declared shape of an ONNX model's first graph input, read straight from the
// protobuf wire format. OpenCV 4.6's cv::dnn does not expose input shapes, and a
// fixed-size model (XFeat's exports) only runs at its own size, so the adapter reads
// it here instead of asking the user to repeat what the file already says.
//
// Only the path ModelProto.graph(7) -> GraphProto.input(11) -> ValueInfoProto.type(2)
// -> TypeProto.tensor_type(1) -> shape(2) -> dim(1) -> dim_value(1) is followed; every
// length is checked against the bytes left, so a truncated or hostile file yields
// "unknown" (an empty vector), never a read out of bounds.

#include <cstddef>
#include <cstdint>
#include <string_view>
#include <vector>

namespace vmap::detail {

class ProtoReader {
 public:
  explicit ProtoReader(std::string_view bytes) : data_(bytes) {}

  [[nodiscard]] bool done() const noexcept { return pos_ >= data_.size() || failed_; }
  [[nodiscard]] bool failed() const noexcept { return failed_; }

  /// Reads the next field key; false at the end or on malformed input.
  bool next(std::uint32_t& field, std::uint32_t& wire) {
    if (done()) return false;
    std::uint64_t key = 0;
    if (!varint(key)) return false;
    field = static_cast<std::uint32_t>(key >> 3);
    wire = static_cast<std::uint32_t>(key & 7u);
    return true;
  }

  bool varint(std::uint64_t& value) {
    value = 0;
    for (int shift = 0; shift < 64; shift += 7) {
      if (pos_ >= data_.size()) return fail();
      const auto byte = static_cast<std::uint8_t>(data_[pos_++]);
      value |= static_cast<std::uint64_t>(byte & 0x7Fu) << shift;
      if ((byte & 0x80u) == 0) return true;
    }
    return fail();
  }

  /// A length-delimited field's bytes.
  bool bytes(std::string_view& out) {
    std::uint64_t n = 0;
    if (!varint(n) || n > data_.size() - pos_) return fail();
    out = data_.substr(pos_, static_cast<std::size_t>(n));
    pos_ += static_cast<std::size_t>(n);
    return true;
  }

  /// Skips a field of the given wire type.
  bool skip(std::uint32_t wire) {
    std::uint64_t v = 0;
    std::string_view s;
    switch (wire) {
      case 0: return varint(v);
      case 1: return advance(8);
      case 2: return bytes(s);
      case 5: return advance(4);
      default: return fail();  // groups (3, 4) are not used by ONNX
    }
  }

 private:
  bool advance(std::size_t n) {
    if (n > data_.size() - pos_) return fail();
    pos_ += n;
    return true;
  }
  bool fail() {
    failed_ = true;
    return false;
  }

  std::string_view data_;
  std::size_t pos_ = 0;
  bool failed_ = false;
};

/// Finds the first length-delimited field `field` of a message; empty if absent.
inline std::string_view proto_sub(std::string_view message, std::uint32_t wanted) {
  ProtoReader r(message);
  std::uint32_t field = 0, wire = 0;
  while (r.next(field, wire)) {
    if (field == wanted && wire == 2) {
      std::string_view s;
      return r.bytes(s) ? s : std::string_view();
    }
    if (!r.skip(wire)) break;
  }
  return {};
}

/// Dimensions of the first input of an ONNX model held in `file_bytes` (-1 for a
/// symbolic dimension); empty when the file does not say or cannot be parsed.
inline std::vector<std::int64_t> onnx_first_input_shape(std::string_view file_bytes) {
  const std::string_view graph = proto_sub(file_bytes, 7);
  const std::string_view input = proto_sub(graph, 11);
  const std::string_view shape = proto_sub(proto_sub(proto_sub(input, 2), 1), 2);
  std::vector<std::int64_t> dims;
  ProtoReader r(shape);
  std::uint32_t field = 0, wire = 0;
  while (r.next(field, wire)) {
    if (field == 1 && wire == 2) {
      std::string_view dim;
      if (!r.bytes(dim)) return {};
      ProtoReader d(dim);
      std::int64_t value = -1;
      std::uint32_t f = 0, w = 0;
      while (d.next(f, w)) {
        if (f == 1 && w == 0) {
          std::uint64_t v = 0;
          if (!d.varint(v)) return {};
          value = static_cast<std::int64_t>(v);
        } else if (!d.skip(w)) {
          return {};
        }
      }
      if (d.failed()) return {};
      dims.push_back(value);
      if (dims.size() > 16) return {};  // no image model has that many dimensions
    } else if (!r.skip(wire)) {
      return {};
    }
  }
  return r.failed() ? std::vector<std::int64_t>{} : dims;
}

}  // namespace vmap::detail
