// Copies of stateful policies: every OpenCV- or network-backed policy
// deep-copies, so a std::vector of per-thread copies runs in parallel. For each policy,
// two copies used from two std::threads (while the original runs too) give exactly the
// results of the original used serially, and a copy owns its network or detector.
#include <vmap/features/akaze.hpp>
#include <vmap/features/orb.hpp>
#include <vmap/features/sift.hpp>
#include <vmap/hooks/dnn_detectors.hpp>
#include <vmap/hooks/pair_matcher_adapters.hpp>
#include <vmap/hooks/xfeat.hpp>
#include <vmap/hooks/xfeat_dense.hpp>

#include "support/protobuf_bytes.hpp"
#include "support/errors.hpp"
#include "support/images.hpp"
#include "support/shared_data.hpp"

#include <doctest/doctest.h>
#include <opencv2/imgcodecs.hpp>

#include <cstdint>
#include <cstring>
#include <exception>
#include <filesystem>
#include <fstream>
#include <initializer_list>
#include <string>
#include <thread>
#include <type_traits>
#include <vector>

// Moves stay cheap and noexcept: a std::vector of policies grows by moving, never by
// re-creating detectors or re-parsing networks.
static_assert(std::is_nothrow_move_constructible_v<vmap::OrbDescriptor>);
static_assert(std::is_nothrow_move_constructible_v<vmap::AkazeDescriptor>);
static_assert(std::is_nothrow_move_constructible_v<vmap::SiftDescriptor>);
static_assert(std::is_nothrow_move_constructible_v<vmap::YoloxDetector>);
static_assert(std::is_nothrow_move_constructible_v<vmap::NanoDetDetector>);
static_assert(std::is_nothrow_move_constructible_v<vmap::FastestDetDetector>);
static_assert(std::is_nothrow_move_constructible_v<vmap::XFeatDescriptor>);
static_assert(std::is_nothrow_move_constructible_v<vmap::XFeatDenseDescriptor>);
static_assert(std::is_nothrow_move_constructible_v<vmap::XFeatDenseMatcher>);
static_assert(std::is_nothrow_move_constructible_v<vmap::DnnPairMatcher>);
static_assert(std::is_copy_constructible_v<vmap::YoloxDetector> && std::is_copy_assignable_v<vmap::YoloxDetector>);
static_assert(std::is_copy_constructible_v<vmap::DnnPairMatcher> && std::is_copy_assignable_v<vmap::DnnPairMatcher>);
static_assert(std::is_copy_constructible_v<vmap::XFeatDenseMatcher>);

namespace {

bool same_mat(const cv::Mat& a, const cv::Mat& b) {
  if (a.size != b.size || a.type() != b.type()) return false;
  if (a.empty()) return true;
  const cv::Mat ca = a.isContinuous() ? a : a.clone(), cb = b.isContinuous() ? b : b.clone();
  return std::memcmp(ca.data, cb.data, ca.total() * ca.elemSize()) == 0;
}

bool same(const vmap::Features& a, const vmap::Features& b) {
  if (a.norm != b.norm || a.image_size != b.image_size || a.size() != b.size()) return false;
  for (std::size_t i = 0; i < a.size(); ++i) {
    const cv::KeyPoint &p = a.keypoints[i], &q = b.keypoints[i];
    if (p.pt != q.pt || p.size != q.size || p.angle != q.angle || p.response != q.response ||
        p.octave != q.octave || p.class_id != q.class_id)
      return false;
  }
  return same_mat(a.descriptors, b.descriptors);
}

bool same(const std::vector<vmap::Detection>& a, const std::vector<vmap::Detection>& b) {
  if (a.size() != b.size()) return false;
  for (std::size_t i = 0; i < a.size(); ++i)
    if (a[i].label != b[i].label || a[i].score != b[i].score || a[i].box != b[i].box) return false;
  return true;
}

bool same(const vmap::Correspondences& a, const vmap::Correspondences& b) {
  return a.points_a == b.points_a && a.points_b == b.points_b && a.confidence == b.confidence && a.cells == b.cells;
}

/// Runs `original` over `inputs` serially; then makes two copies of it (after it ran,
/// so its buffers are allocated and would be shared by a shallow copy) and runs each
/// copy over the same inputs on its own std::thread while the original runs them again
/// on this one. Every run must give exactly the serial results. `run(policy, inputs, i)`
/// gives the result of input i. Returns the serial results.
template <class P, class Run>
auto check_copies_agree(P& original, const std::vector<cv::Mat>& inputs, Run run) {
  using Result = decltype(run(original, inputs, std::size_t{0}));
  std::vector<Result> serial;
  for (std::size_t i = 0; i < inputs.size(); ++i) serial.push_back(run(original, inputs, i));

  std::vector<P> copies(2, original);  // the per-thread copies
  std::vector<std::vector<Result>> results(copies.size());
  std::vector<std::string> errors(copies.size());
  std::vector<std::thread> threads;
  for (std::size_t k = 0; k < copies.size(); ++k)
    threads.emplace_back([&, k] {
      try {
        for (std::size_t i = 0; i < inputs.size(); ++i) results[k].push_back(run(copies[k], inputs, i));
      } catch (const std::exception& e) {
        errors[k] = e.what();
      }
    });
  std::vector<Result> again;
  for (std::size_t i = 0; i < inputs.size(); ++i) again.push_back(run(original, inputs, i));
  for (auto& t : threads) t.join();

  for (std::size_t k = 0; k < copies.size(); ++k) {
    CAPTURE(k);
    CHECK(errors[k].empty());
    REQUIRE(results[k].size() == serial.size());
    for (std::size_t i = 0; i < serial.size(); ++i) CHECK(same(results[k][i], serial[i]));
  }
  REQUIRE(again.size() == serial.size());
  for (std::size_t i = 0; i < serial.size(); ++i) CHECK(same(again[i], serial[i]));
  return serial;
}

const auto extract = [](auto& d, const std::vector<cv::Mat>& in, std::size_t i) { return d.extract(in[i]); };
const auto detect = [](auto& d, const std::vector<cv::Mat>& in, std::size_t i) { return d.detect(in[i]); };
const auto match_next = [](auto& m, const std::vector<cv::Mat>& in, std::size_t i) {
  return m.match_pair(in[i], in[(i + 1) % in.size()]);
};

std::vector<cv::Mat> synthetic_images() {
  return {vmap::test::textured_image(3, {320, 240}), vmap::test::textured_image(4, {320, 240})};
}

/// Two real frames (tum_fr1_rpy, the office with a person, a chair and a cup).
std::vector<cv::Mat> office_frames() {
  std::vector<cv::Mat> out;
  for (const char* name : {"1305031253.529706.jpg", "1305031229.528748.jpg"}) {
    out.push_back(cv::imread(vmap::test::data_path(std::string("tum_fr1_rpy/rgb/") + name).string()));
    REQUIRE(out.back().size() == cv::Size(640, 480));
  }
  return out;
}

// A tiny LoFTR-shaped ONNX model for DnnPairMatcher, written here as protobuf bytes (no
// LoFTR export runs in OpenCV 4.6, see ../shared/models/README.md): inputs image0 and
// image1 1x1x16x16; each is average-pooled over 8x8 cells (2x2 = 4 cells), and the
// confidence matrix is the outer product of the two cell means, a 4x4 matrix in [0, 1].
using vmap::test::field_bytes;
using vmap::test::field_varint;

std::string node(const std::string& op, const std::vector<std::string>& in, const std::string& out,
                 const std::string& attributes = {}) {
  std::string n;
  for (const auto& i : in) n += field_bytes(1, i);
  return n + field_bytes(2, out) + field_bytes(3, out) + field_bytes(4, op) + attributes;
}
std::string ints_attribute(const std::string& name, std::initializer_list<std::uint64_t> values) {
  std::string a = field_bytes(1, name) + field_varint(20, 7);  // type INTS
  for (const auto v : values) a += field_varint(8, v);
  return field_bytes(5, a);
}
std::string int64_tensor(const std::string& name, const std::vector<std::int64_t>& values) {
  std::string raw;
  for (const std::int64_t v : values)
    for (int b = 0; b < 8; ++b) raw += static_cast<char>((static_cast<std::uint64_t>(v) >> (8 * b)) & 0xFFu);
  return field_varint(1, values.size()) + field_varint(2, 7) + field_bytes(8, name) + field_bytes(9, raw);
}
std::string float_value(const std::string& name, const std::vector<std::uint64_t>& dims) {
  std::string shape;
  for (const auto d : dims) shape += field_bytes(1, field_varint(1, d));
  return field_bytes(1, name) + field_bytes(2, field_bytes(1, field_varint(1, 1) + field_bytes(2, shape)));
}

std::filesystem::path tiny_pair_model() {
  const std::string pool = ints_attribute("kernel_shape", {8, 8}) + ints_attribute("strides", {8, 8});
  std::string graph = field_bytes(1, node("AveragePool", {"image0"}, "pool0", pool)) +
                      field_bytes(1, node("AveragePool", {"image1"}, "pool1", pool)) +
                      field_bytes(1, node("Reshape", {"pool0", "column"}, "a")) +
                      field_bytes(1, node("Reshape", {"pool1", "row"}, "b")) +
                      field_bytes(1, node("MatMul", {"a", "b"}, "confidence")) + field_bytes(2, "tiny_pair");
  graph += field_bytes(5, int64_tensor("column", {4, 1})) + field_bytes(5, int64_tensor("row", {1, 4}));
  graph += field_bytes(11, float_value("image0", {1, 1, 16, 16})) + field_bytes(11, float_value("image1", {1, 1, 16, 16}));
  graph += field_bytes(12, float_value("confidence", {4, 4}));
  const std::string model = field_varint(1, 7) + field_bytes(8, field_varint(2, 11)) + field_bytes(7, graph);
  const auto file = vmap::test::scratch_dir("hooks_copies_pair") / "tiny_pair.onnx";
  std::ofstream(file, std::ios::binary) << model;
  return file;
}

}  // namespace

// ---- OpenCV feature detectors (self-contained) -------------------------------------

TEST_CASE("copies: ORB copies on two threads equal one ORB used serially") {
  vmap::OrbDescriptor orb({.features = 300});
  const auto serial = check_copies_agree(orb, synthetic_images(), extract);
  for (const auto& f : serial) CHECK(f.size() > 250);  // the cap is 300
}

TEST_CASE("copies: A-KAZE and SIFT copies on two threads equal one object used serially") {
  vmap::AkazeDescriptor akaze;
  for (const auto& f : check_copies_agree(akaze, synthetic_images(), extract)) CHECK(f.size() > 50);
  vmap::SiftDescriptor sift({.features = 200});
  for (const auto& f : check_copies_agree(sift, synthetic_images(), extract)) CHECK(f.size() >= 200);
}

TEST_CASE("copies: an ORB copy owns its detector; assignment takes the other's options") {
  const cv::Mat img = vmap::test::textured_image(3, {320, 240});
  vmap::OrbDescriptor a({.features = 300});
  const vmap::Features before = a.extract(img);
  vmap::OrbDescriptor b = a;
  b = vmap::OrbDescriptor({.features = 40});  // replacing the copy's detector leaves a's alone
  CHECK(b.options().features == 40);
  CHECK(b.extract(img).size() == 40);
  CHECK(a.options().features == 300);
  CHECK(same(a.extract(img), before));
  vmap::OrbDescriptor c({.features = 40});
  c = a;  // copy assignment: a's options and a detector made from them
  CHECK(c.options().features == 300);
  CHECK(same(c.extract(img), before));
  const vmap::OrbDescriptor& self = c;
  c = self;  // self-assignment keeps it working
  CHECK(same(c.extract(img), before));
}

TEST_CASE("copies: a descriptor's buffer never writes over an earlier input image") {
  // An 8-bit grey image is used without a copy, so the buffer still holds the caller's
  // pixels when the next image, a colour one of the same size, is converted into it.
  const cv::Mat grey = vmap::test::textured_image(3, {320, 240});
  const cv::Mat kept = grey.clone();
  cv::Mat colour;
  cv::cvtColor(vmap::test::textured_image(4, {320, 240}), colour, cv::COLOR_GRAY2BGR);
  vmap::OrbDescriptor orb({.features = 100});
  const vmap::Features first = orb.extract(grey);
  (void)orb.extract(colour);
  CHECK(cv::norm(grey, kept, cv::NORM_INF) == 0.0);
  CHECK(same(orb.extract(grey), first));
}

TEST_CASE("copies: DnnPairMatcher copies on two threads equal one matcher used serially") {
  vmap::DnnPairMatcher matcher({.model = tiny_pair_model(), .input_size = {16, 16}, .threshold = 0.0f});
  std::vector<cv::Mat> images;
  for (const std::uint64_t seed : {3, 4, 5}) images.push_back(vmap::test::textured_image(seed, {64, 64}));
  for (const auto& c : check_copies_agree(matcher, images, match_next)) {
    CHECK(c.cells == 4);
    CHECK(c.size() == 1);  // an outer product has one mutual maximum: brightest cell to brightest cell
  }
  vmap::DnnPairMatcher other = matcher;
  other = matcher;  // copy assignment parses the model again as well
  CHECK(same(other.match_pair(images[0], images[1]), matcher.match_pair(images[0], images[1])));
}

// ---- networks (ONNX models from ../shared/models) -----------------------------------

TEST_SUITE("data") {
  TEST_CASE("copies: a DnnNet copy runs its own cv::dnn::Net, parsed from the kept model bytes") {
    // FastestDet: the smallest model (1 MB). Copied to a scratch file that is then
    // removed: a copy must not need the file again.
    const auto dir = vmap::test::scratch_dir("hooks_copies");
    const auto file = dir / "model.onnx";
    std::filesystem::copy_file(vmap::test::model_path("FastestDet.onnx"), file);
    vmap::detail::DnnNet a(file, "test");
    std::filesystem::remove(file);
    vmap::detail::DnnNet b = a;
    CHECK(b.bytes == a.bytes);  // the immutable bytes are shared, the network is not
    CHECK(b.output_names == a.output_names);
    CHECK(b.outputs.empty());
    const cv::Mat image = vmap::test::textured_image(3, {352, 352});
    cv::Mat bgr, blob;
    cv::cvtColor(image, bgr, cv::COLOR_GRAY2BGR);
    cv::dnn::blobFromImage(bgr, blob, 1.0 / 255.0, cv::Size(), cv::Scalar(), false, false, CV_32F);
    a.forward(blob, "test", "1x3x352x352");
    b.forward(blob, "test", "1x3x352x352");
    REQUIRE(a.outputs.size() == 1);
    REQUIRE(b.outputs.size() == 1);
    CHECK(same_mat(a.outputs[0], b.outputs[0]));
    // Each net has its own layer objects (and with them its own blobs); the control: a
    // plain cv::dnn::Net copy, a handle to the same network, has the same ones.
    const int id = a.net.getLayerId(a.net.getLayerNames().front());
    CHECK(a.net.getLayer(id).get() != b.net.getLayer(id).get());
    cv::dnn::Net shallow = a.net;
    CHECK(shallow.getLayer(id).get() == a.net.getLayer(id).get());
    // Copy assignment re-parses as well; a default (empty) net copies to an empty one.
    vmap::detail::DnnNet c;
    c = a;
    c.forward(blob, "test", "1x3x352x352");
    CHECK(c.net.getLayer(id).get() != a.net.getLayer(id).get());
    CHECK(same_mat(c.outputs[0], b.outputs[0]));
    const vmap::detail::DnnNet empty;
    const vmap::detail::DnnNet empty_copy = empty;
    CHECK(empty_copy.net.empty());
    CHECK(empty_copy.bytes == nullptr);
  }

  TEST_CASE("copies: YOLOX, NanoDet and FastestDet copies on two threads equal one detector used serially") {
    const std::vector<cv::Mat> frames = office_frames();
    const auto total = [](const std::vector<std::vector<vmap::Detection>>& r) {
      std::size_t n = 0;
      for (const auto& d : r) n += d.size();
      return n;
    };
    {
      vmap::YoloxDetector yolox({.model = vmap::test::model_path("yolox_nano.onnx")});
      CHECK(total(check_copies_agree(yolox, frames, detect)) > 0);
    }
    {
      vmap::NanoDetDetector nanodet({.model = vmap::test::model_path("nanodet_m_320.onnx"), .score_threshold = 0.3f});
      CHECK(total(check_copies_agree(nanodet, frames, detect)) > 0);
    }
    {
      vmap::FastestDetDetector fastest({.model = vmap::test::model_path("FastestDet.onnx"), .score_threshold = 0.3f});
      CHECK(total(check_copies_agree(fastest, frames, detect)) > 0);
    }
  }

  TEST_CASE("copies: a detector copy outlives the original and its model file") {
    const auto dir = vmap::test::scratch_dir("hooks_copies_detector");
    const auto file = dir / "fastestdet.onnx";
    std::filesystem::copy_file(vmap::test::model_path("FastestDet.onnx"), file);
    const cv::Mat frame = office_frames().front();
    std::vector<vmap::Detection> want;
    std::vector<vmap::FastestDetDetector> copies;
    {
      vmap::FastestDetDetector original({.model = file, .score_threshold = 0.3f});
      want = original.detect(frame);
      copies.push_back(original);
    }
    std::filesystem::remove(file);
    copies.push_back(copies.front());  // a copy of a copy, with no file left
    CHECK(copies[1].classes() == 80);
    CHECK(same(copies[0].detect(frame), want));
    CHECK(same(copies[1].detect(frame), want));
  }

  TEST_CASE("copies: XFeat (any-size model) copies on two threads equal one XFeat used serially") {
    std::vector<cv::Mat> small;
    for (const cv::Mat& f : office_frames()) small.push_back(f(cv::Rect(160, 120, 256, 192)).clone());
    vmap::XFeatDescriptor xfeat({.model = vmap::test::model_path("xfeat_anysize.onnx"), .top_k = 300});
    REQUIRE(xfeat.model_kind() == vmap::XFeatModelKind::any_size);
    for (const auto& f : check_copies_agree(xfeat, small, extract)) CHECK(f.size() == 300);
    // A copy keeps the model's kind and sizes without probing the model again.
    const vmap::XFeatDescriptor copy = xfeat;
    CHECK(copy.model_kind() == vmap::XFeatModelKind::any_size);
    CHECK(copy.network_size({250, 190}) == cv::Size(224, 160));
  }

  TEST_CASE("copies: dense XFeat descriptor and matcher copies on two threads equal one object used serially") {
    // Four images: more than the matcher's cache of three, so the copies run the network.
    std::vector<cv::Mat> small;
    for (const cv::Mat& f : office_frames())
      for (const int x : {0, 320}) small.push_back(f(cv::Rect(x, 128, 320, 224)).clone());
    vmap::XFeatDenseDescriptor dense({.model = vmap::test::model_path("xfeat_320x224.onnx")});
    for (const auto& f : check_copies_agree(dense, {small[0], small[3]}, extract)) CHECK(f.size() == 40u * 28u);
    vmap::XFeatDenseMatcher matcher({.model = vmap::test::model_path("xfeat_320x224.onnx")});
    for (const auto& c : check_copies_agree(matcher, small, match_next)) CHECK(c.size() > 20);
    // A copy starts with its own copy of the original's cache (the last images): no
    // network run, and the cached features are not the original's objects.
    vmap::XFeatDenseMatcher copy = matcher;
    const std::size_t runs = copy.network_runs();
    CHECK(same(copy.match_pair(small[2], small[3]), matcher.match_pair(small[2], small[3])));
    CHECK(copy.network_runs() == runs);
    CHECK(&copy.features(small[3]) != &matcher.features(small[3]));
    CHECK(copy.features(small[3]).descriptors.data != matcher.features(small[3]).descriptors.data);
    CHECK(same(copy.features(small[3]), matcher.features(small[3])));
  }
}
