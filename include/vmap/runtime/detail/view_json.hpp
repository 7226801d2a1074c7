#pragma once

// The page's data as JSON text (runtime/view.hpp: data.js and the loops' matches, which
// the page reads as scripts). The run-time layer's own header.

#include <charconv>
#include <cmath>
#include <cstdio>
#include <string>
#include <string_view>
#include <vector>

namespace vmap::detail {

/// JSON text for the page's data (the page reads it as a script: data.js). Values follow
/// key() in an object, or item() in a list; open() and close() make either.
class ViewJson {
 public:
  /// Text as it is (around the JSON, or a literal value such as null).
  ViewJson& raw(std::string_view s) {
    value_next_ = false;
    out_ += s;
    return *this;
  }
  ViewJson& str(std::string_view s) {
    value_next_ = false;
    out_ += '"';
    for (const char c : s) {
      const auto u = static_cast<unsigned char>(c);
      if (c == '"' || c == '\\') {
        out_ += '\\';
        out_ += c;
      } else if (u < 0x20) {
        char buf[8];
        std::snprintf(buf, sizeof buf, "\\u%04x", u);
        out_ += buf;
      } else {
        out_ += c;  // UTF-8 as it is; the page is read as UTF-8
      }
    }
    out_ += '"';
    return *this;
  }
  /// A finite number in its shortest form that reads back exactly, or null.
  ViewJson& num(double v) {
    if (!std::isfinite(v)) return raw("null");
    char buf[32];
    const auto r = std::to_chars(buf, buf + sizeof buf, v);
    return raw(std::string_view(buf, static_cast<std::size_t>(r.ptr - buf)));
  }
  /// A finite number with `digits` significant digits (positions, scores), or null.
  ViewJson& num(double v, int digits) {
    if (!std::isfinite(v)) return raw("null");
    char buf[40];
    const auto r = std::to_chars(buf, buf + sizeof buf, v, std::chars_format::general, digits);
    return raw(std::string_view(buf, static_cast<std::size_t>(r.ptr - buf)));
  }
  ViewJson& integer(long long v) {
    char buf[24];
    const auto r = std::to_chars(buf, buf + sizeof buf, v);
    return raw(std::string_view(buf, static_cast<std::size_t>(r.ptr - buf)));
  }
  /// An object's key; its value follows.
  ViewJson& key(std::string_view k) {
    comma();
    str(k);
    out_ += ':';
    value_next_ = true;
    return *this;
  }
  /// A list's next value follows.
  ViewJson& item() {
    comma();
    value_next_ = true;
    return *this;
  }
  /// Opens an object ('{') or a list ('['): as the value of a key or an item, or alone.
  ViewJson& open(char c) {
    if (!value_next_) comma();
    value_next_ = false;
    out_ += c;
    first_ = true;
    return *this;
  }
  ViewJson& close(char c) {
    out_ += c;
    first_ = false;
    return *this;
  }
  template <class T, class F>
  ViewJson& list(std::string_view k, const std::vector<T>& v, F&& each) {
    key(k).open('[');
    for (const T& x : v) {
      item();
      each(x);
    }
    return close(']');
  }
  [[nodiscard]] std::string& text() noexcept { return out_; }

 private:
  /// A comma before all but the first entry of an object or list.
  void comma() {
    if (!first_) out_ += ',';
    first_ = false;
  }
  std::string out_;
  bool first_ = true;
  bool value_next_ = false;
};

}  // namespace vmap::detail
