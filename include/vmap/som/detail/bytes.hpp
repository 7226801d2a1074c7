#pragma once

// Little helpers for the versioned binary files of som/ (GCS maps). Every read is
// bounds-checked against the bytes that are really there, so a truncated or hostile
// file is a vmap::Error before any allocation it asks for.

#include <vmap/core/error.hpp>

#include <cstdint>
#include <cstring>
#include <string>
#include <string_view>
#include <type_traits>
#include <utility>

namespace vmap::detail {

class ByteWriter {
 public:
  template <class T>
    requires std::is_trivially_copyable_v<T>
  void put(const T& value) {
    const auto* p = reinterpret_cast<const char*>(&value);
    bytes_.append(p, sizeof(T));
  }
  void put_bytes(std::string_view s) { bytes_.append(s.data(), s.size()); }
  [[nodiscard]] const std::string& bytes() const noexcept { return bytes_; }

 private:
  std::string bytes_;
};

class ByteReader {
 public:
  ByteReader(std::string_view bytes, std::string what) : bytes_(bytes), what_(std::move(what)) {}

  template <class T>
    requires std::is_trivially_copyable_v<T>
  T get(const char* field) {
    require(sizeof(T), field);
    T value;
    std::memcpy(&value, bytes_.data() + pos_, sizeof(T));
    pos_ += sizeof(T);
    return value;
  }

  std::string_view get_bytes(std::size_t n, const char* field) {
    require(n, field);
    auto s = bytes_.substr(pos_, n);
    pos_ += n;
    return s;
  }

  [[nodiscard]] std::size_t remaining() const noexcept { return bytes_.size() - pos_; }

  /// Fails unless `count` items of `item_bytes` each still fit in the file: checked
  /// before a vector of `count` items is allocated.
  void require_items(std::uint64_t count, std::size_t item_bytes, const char* field) const {
    if (item_bytes != 0 && count > remaining() / item_bytes)
      fail(what_ + ": truncated or corrupt (" + field + " claims " + std::to_string(count) +
           " items, the file holds fewer)");
  }

  void expect_end() const {
    if (remaining() != 0)
      fail(what_ + ": corrupt (" + std::to_string(remaining()) + " unexpected bytes after the data)");
  }

  [[nodiscard]] const std::string& what() const noexcept { return what_; }

 private:
  void require(std::size_t n, const char* field) const {
    if (n > remaining()) fail(what_ + ": truncated (ends inside " + field + ")");
  }

  std::string_view bytes_;
  std::string what_;
  std::size_t pos_ = 0;
};

}  // namespace vmap::detail
