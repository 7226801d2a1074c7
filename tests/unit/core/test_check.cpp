// detail::check builds its message only when the condition fails:
// a composed message is a callable, run once on failure and never when the check holds.
#include <vmap/core/error.hpp>

#include "support/errors.hpp"

#include <doctest/doctest.h>

#include <string>

using vmap::test::error_of;

TEST_CASE("check: a callable message is not built when the condition holds") {
  int built = 0;
  const auto message = [&] {
    ++built;
    return "frame " + std::to_string(17) + " is empty";
  };
  for (int i = 0; i < 100; ++i) vmap::detail::check(true, message);
  CHECK(built == 0);
  CHECK(error_of([&] { vmap::detail::check(false, message); }) == "frame 17 is empty");
  CHECK(built == 1);
}

TEST_CASE("check: literal and string messages are thrown as given") {
  CHECK(error_of([] { vmap::detail::check(false, "a literal"); }) == "a literal");
  const std::string s = "a string";
  CHECK(error_of([&] { vmap::detail::check(false, s); }) == "a string");
  CHECK(error_of([] { vmap::detail::check(true, "never"); }) == "no error");
  // A callable may return anything a std::string is made from.
  CHECK(error_of([] { vmap::detail::check(false, [] { return "from a const char*"; }); }) == "from a const char*");
}
