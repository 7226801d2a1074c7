// Class-name files as untrusted input (issue 13): a folder or a device such as
// /dev/zero is refused by name before anything is read.
#include <vmap/hooks/class_names.hpp>

#include "support/errors.hpp"
#include "support/shared_data.hpp"

#include <doctest/doctest.h>

#include <string>

TEST_CASE("class names: a folder or a device is an error naming it") {
  const auto dir = vmap::test::scratch_dir("hooks_load_limits");
  CHECK(vmap::test::error_of([&] { (void)vmap::read_class_names(dir); })
            .find("class names file '" + dir.string() + "' is a folder") != std::string::npos);
  CHECK(vmap::test::error_of([] { (void)vmap::read_class_names("/dev/zero"); })
            .find("class names file '/dev/zero' is not a regular file") != std::string::npos);
}
