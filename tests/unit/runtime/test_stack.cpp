#include "support/errors.hpp"
#include "support/shared_data.hpp"

#include <vmap/memory/visual_memory.hpp>
#include <vmap/runtime/policies.hpp>
#include <vmap/runtime/stack.hpp>

#include <doctest/doctest.h>

#include <array>
#include <string>

namespace {

const vmap::Camera tum_camera{.fx = 517.3, .fy = 516.5, .cx = 318.6, .cy = 255.3,
                              .distortion = {0.2624, -0.9531, -0.0054, 0.0026, 1.1633}, .image_size = {640, 480}};

/// The policy records of the memory with_policies builds for `s` (ORB, A-KAZE, SIFT).
std::array<std::string, 4> memory_records(const vmap::PolicyStack& s) {
  return vmap::with_policies(s, vmap::StackUse::memory, [](auto d, auto m, auto e) {
    vmap::VisualMemory memory(std::move(d), std::move(m), std::move(e), vmap::InlierRatio{});
    return memory.policy_records();
  });
}

}  // namespace

TEST_CASE("names read back: to_string and from_string of the methods and descriptors") {
  for (auto m : {vmap::RobustMethod::magsac, vmap::RobustMethod::ransac, vmap::RobustMethod::lmeds,
                 vmap::RobustMethod::eight_point})
    CHECK(vmap::from_string<vmap::RobustMethod>(vmap::to_string(m)) == m);
  CHECK(vmap::to_string(vmap::RobustMethod::eight_point) == "8point");
  CHECK_FALSE(vmap::from_string<vmap::RobustMethod>("magsak").has_value());
  CHECK(vmap::test::error_of([] { (void)vmap::parse<vmap::RobustMethod>("magsak", "--estimator"); }) ==
        "--estimator: unknown name 'magsak' (choose magsac, ransac, lmeds or 8point)");
  CHECK(vmap::from_string<vmap::DescriptorKind>("xfeat-star") == vmap::DescriptorKind::xfeat_star);
  CHECK(vmap::to_string(vmap::DescriptorKind::xfeat_dense) == "xfeat-dense");
}

TEST_CASE("a policy stack is a value: to_string reads back, invalid stacks are refused by name") {
  CHECK(vmap::to_string(vmap::PolicyStack{}) == "orb method=magsac");
  const auto s = vmap::PolicyStack::from_string("sift features=500 method=ransac");
  CHECK(s.descriptor == vmap::DescriptorKind::sift);
  CHECK(s.features == 500);
  CHECK(s.method == vmap::RobustMethod::ransac);
  CHECK(vmap::to_string(s) == "sift features=500 method=ransac");

  vmap::PolicyStack star;
  star.descriptor = vmap::DescriptorKind::xfeat_star;
  star.model = "/models dir/xfeat \"any\".onnx";
  star.refine_model = "/m/xfeat_fine.onnx";
  star.camera = tum_camera;
  star.camera_source = "tum.yaml";
  const std::string text = vmap::to_string(star);
  CHECK(text == "xfeat-star model=\"/models dir/xfeat \\\"any\\\".onnx\" refine_model=\"/m/xfeat_fine.onnx\" method=magsac "
                "camera=(pinhole fx=517.3 fy=516.5 cx=318.6 cy=255.3 distortion=[0.2624 -0.9531 -0.0054 0.0026 1.1633] "
                "size=640x480) camera_source=\"tum.yaml\"");
  const auto back = vmap::PolicyStack::from_string(text);
  CHECK(back == star);
  CHECK(back.camera_source == "tum.yaml");
  CHECK(back.camera->distortion == tum_camera.distortion);
  // The source of the calibration is not part of the stack's identity.
  auto elsewhere = star;
  elsewhere.camera_source = "other.yaml";
  CHECK(elsewhere == star);
  elsewhere.camera->fx = 500.0;
  CHECK_FALSE(elsewhere == star);

  CHECK(vmap::test::error_of([] { (void)vmap::PolicyStack::from_string("orbb"); }) ==
        "policy stack 'orbb': the descriptor: unknown name 'orbb' (choose orb, akaze, sift, xfeat, xfeat-dense or xfeat-star)");
  CHECK(vmap::test::error_of([] { (void)vmap::PolicyStack::from_string("orb features=0"); }) ==
        "policy stack 'orb features=0': features must be a whole number in [1, 100000]");
  CHECK(vmap::test::error_of([] { (void)vmap::PolicyStack::from_string("xfeat"); }) ==
        "policy stack 'xfeat': xfeat needs a model file (an XFeat ONNX export such as xfeat_320x224.onnx)");
  CHECK(vmap::test::error_of([] { (void)vmap::PolicyStack::from_string("orb model=\"x.onnx\""); }) ==
        "policy stack 'orb model=\"x.onnx\"': orb takes no model file");
  CHECK(vmap::test::error_of([] { (void)vmap::PolicyStack::from_string("orb colour=red"); }) ==
        "policy stack 'orb colour=red': unknown field 'colour' (features, model, refine_model, method, camera, "
        "camera_source)");
  CHECK(vmap::test::error_of([] { (void)vmap::PolicyStack::from_string("orb camera=(pinhole fx=1)"); })
            .find("the camera is not") != std::string::npos);
}

TEST_CASE("a memory records its stack once, as its policies' records, and the stack reads back from them") {
  vmap::PolicyStack calibrated;
  calibrated.camera = tum_camera;
  for (const auto& s : {vmap::PolicyStack{}, vmap::PolicyStack::from_string("orb features=500 method=ransac"),
                        vmap::PolicyStack::from_string("akaze method=lmeds"),
                        vmap::PolicyStack::from_string("sift features=800 method=8point"), calibrated}) {
    CAPTURE(vmap::to_string(s));
    const auto records = memory_records(s);
    CHECK(vmap::policy_records(s) == records);
    CHECK(vmap::stack_of_policies(records, "memory 'm'") == s);
  }
  // XFeat's records name their models; computed without loading them.
  vmap::PolicyStack star;
  star.descriptor = vmap::DescriptorKind::xfeat_star;
  star.model = "/m/xfeat_anysize.onnx";
  star.refine_model = "/m/xfeat_fine.onnx";
  const auto records = vmap::policy_records(star);
  CHECK(records[0] == "XFeatDenseDescriptor model=\"/m/xfeat_anysize.onnx\" input_size=0x0 grid=refinable");
  CHECK(records[1] == "DenseMutualMatcher normalise=1");
  CHECK(records[2] == "XFeatRefined model=\"/m/xfeat_fine.onnx\" min_confidence=0.25 estimator=(" +
                          vmap::FundamentalEstimator{}.describe() + ")");
  CHECK(vmap::stack_of_policies(records, "memory 'm'") == star);
  auto dense = star;
  dense.descriptor = vmap::DescriptorKind::xfeat_dense;
  dense.refine_model.clear();
  CHECK(vmap::stack_of_policies(vmap::policy_records(dense), "memory 'm'") == dense);
  auto sparse = dense;
  sparse.descriptor = vmap::DescriptorKind::xfeat;
  sparse.features = 500;
  CHECK(vmap::stack_of_policies(vmap::policy_records(sparse), "memory 'm'") == sparse);

  // Policies outside the shipped stacks are refused by name: another ORB option, another
  // estimator threshold, an unknown descriptor.
  auto other = vmap::policy_records(vmap::PolicyStack{});
  other[0] = vmap::OrbDescriptor({.features = 1000, .levels = 4}).describe();
  const std::string why = vmap::test::error_of([&] { (void)vmap::stack_of_policies(other, "memory 'm'"); });
  CHECK(why.find("memory 'm': its policies are not one of vmap's stacks (options the stack does not set") == 0);
  other = vmap::policy_records(vmap::PolicyStack{});
  other[2] = vmap::FundamentalEstimator({.threshold_px = 2.0}).describe();
  CHECK(vmap::test::error_of([&] { (void)vmap::stack_of_policies(other, "memory 'm'"); })
            .find("options the stack does not set") != std::string::npos);
  other[0] = "MyDescriptor size=3";
  CHECK(vmap::test::error_of([&] { (void)vmap::stack_of_policies(other, "memory 'm'"); })
            .find("an unknown descriptor") != std::string::npos);
}

TEST_CASE("the stack note of stores written before XFeat's policies described themselves reads back") {
  const auto xfeat = vmap::stack_of_legacy_note(
      R"({"camera":null,"estimator":"ransac","features":"xfeat","model":"/m/x.onnx","nfeatures":500,"refine_model":""})",
      "note");
  CHECK(vmap::to_string(xfeat) == "xfeat features=500 model=\"/m/x.onnx\" method=ransac");
  const auto camera = vmap::stack_of_legacy_note(
      R"({"camera":{"cx":318.6,"cy":255.3,"distortion":[0.2624,-0.9531,-0.0054,0.0026,1.1633],"file":"/d/tum.yaml",)"
      R"("fx":517.3,"fy":516.5,"height":480,"lens":"pinhole","width":640},"estimator":"magsac","features":"orb",)"
      R"("model":"","nfeatures":1000,"refine_model":""})",
      "note");
  CHECK(camera.camera_source == "/d/tum.yaml");
  CHECK(camera.camera->describe() == tum_camera.describe());
  CHECK(vmap::test::error_of([] { (void)vmap::stack_of_legacy_note("{\"features\":3}", "memory 'm': its stack"); }) ==
        "memory 'm': its stack is not valid: its 'features' is missing or of another type");
  CHECK(vmap::test::error_of([] { (void)vmap::stack_of_legacy_note("{\"a\":", "n"); }) ==
        "n is not valid: unexpected end at offset 5");
}
