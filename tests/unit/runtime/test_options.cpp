// The run-time layer's checks of what a user gives, with messages that name each input
// as the front end does: option names, the stack's words, the frame range, the vocabulary
// to learn, the candidate source.

#include "support/errors.hpp"

#include <vmap/keyframe/selector.hpp>
#include <vmap/lcd/loop_engine.hpp>
#include <vmap/runtime/frame_range.hpp>
#include <vmap/runtime/loop_detector.hpp>
#include <vmap/runtime/option_names.hpp>
#include <vmap/runtime/stack_choice.hpp>
#include <vmap/runtime/vocabulary.hpp>

#include <doctest/doctest.h>

#include <string>

using vmap::CandidateIndex;
using vmap::OptionNames;
using vmap::test::error_of;

TEST_CASE("option names: keywords as given, flags with dashes, a front end's own names") {
  const OptionNames py = OptionNames::keywords();
  const OptionNames cli = OptionNames::command_line({{"model", "--features-model"}});
  CHECK(py("refine_model") == "refine_model");
  CHECK(cli("refine_model") == "--refine-model");
  CHECK(cli("model") == "--features-model");
  CHECK(py.with_value("rank", "tree") == "rank=tree");
  CHECK(cli.with_value("rank", "tree") == "--rank tree");
  CHECK(vmap::parse_option<vmap::KeyRule>("current", "rule", "rule", cli) == vmap::KeyRule::current_frame);
  CHECK(error_of([&] { (void)vmap::parse_option<vmap::KeyRule>("next", "rule", "rule", cli); }) ==
        "--rule: unknown rule 'next' (choose previous or current)");
  CHECK(error_of([&] { (void)vmap::parse_option<CandidateIndex>("fast", "rank", "", py); }) ==
        "rank: unknown 'fast' (choose tree, tree_ranked, bow or brute_force)");
}

TEST_CASE("candidate sources: the enumerators' names, the old spelling all read too") {
  for (auto c : {CandidateIndex::tree, CandidateIndex::tree_ranked, CandidateIndex::bow, CandidateIndex::brute_force})
    CHECK(vmap::from_string<CandidateIndex>(vmap::to_string(c)) == c);
  CHECK(vmap::to_string(CandidateIndex::brute_force) == "brute_force");
  CHECK(vmap::from_string<CandidateIndex>("all") == CandidateIndex::brute_force);
  CHECK(vmap::from_string<CandidateIndex>("brute_force") == CandidateIndex::brute_force);
  CHECK(vmap::to_string(CandidateIndex::tree_ranked) == "tree_ranked");
  CHECK_FALSE(vmap::from_string<CandidateIndex>("Tree").has_value());

  // The default: what is given decides.
  CHECK(vmap::default_candidate_index(true, true) == CandidateIndex::tree_ranked);
  CHECK(vmap::default_candidate_index(false, true) == CandidateIndex::bow);
  CHECK(vmap::default_candidate_index(true, false) == CandidateIndex::tree);
  CHECK(vmap::default_candidate_index(false, false) == CandidateIndex::brute_force);

  // What a source needs and is not given, named as the front end names it.
  CHECK(error_of([] { vmap::check_candidate_source(CandidateIndex::tree, false, true); }) ==
        "rank=tree needs labels (rank=bow or all need none): give labels");
  CHECK(error_of([] {
          vmap::check_candidate_source(CandidateIndex::tree_ranked, false, true,
                                       OptionNames::command_line({{"labels", "--labels FILE"}}));
        }) == "--rank tree_ranked needs labels (--rank bow or all need none): give --labels FILE");
  CHECK(error_of([] { vmap::check_candidate_source(CandidateIndex::bow, false, false); }) ==
        "rank=bow ranks by bag of words: give vocabulary");
  CHECK(error_of([] { vmap::check_candidate_source(CandidateIndex::brute_force, false, false); }) == "no error");
  CHECK(error_of([] { vmap::check_candidate_source(CandidateIndex::tree, true, false); }) == "no error");
}

TEST_CASE("loop options: the library checks every value, the consistency count too") {
  vmap::LoopOptions o;
  CHECK(error_of([&] { vmap::check_loop_options(o, "LoopOptions"); }) == "no error");
  o.decision.min_confidence = 1.5;
  CHECK(error_of([&] { vmap::check_loop_options(o, "LoopOptions"); }) ==
        "LoopOptions.decision.min_confidence must be in [0, 1], got 1.500000");
  o = {};
  o.temporal_consistency = 1001;
  CHECK(error_of([&] { vmap::check_loop_options(o, "LoopOptions"); }) ==
        "LoopOptions.temporal_consistency must be <= 1000, got 1001");
  o.temporal_consistency = vmap::max_temporal_consistency;
  CHECK(error_of([&] { vmap::check_loop_options(o, "LoopOptions"); }) == "no error");
  o = {};
  o.index = CandidateIndex::bow;
  o.top_k = 0;
  CHECK(error_of([&] { vmap::check_loop_options(o, "LoopOptions"); }) ==
        "LoopOptions.top_k must be >= 1 for the bow candidate source");
}

TEST_CASE("stack words: checked once, named as the front end names them") {
  const auto cli = OptionNames::command_line();
  const vmap::PolicyStack s = vmap::stack_of({.descriptor = "sift", .features = 500, .method = "ransac"});
  CHECK(s.descriptor == vmap::DescriptorKind::sift);
  CHECK(s.features == 500);
  CHECK(s.method == vmap::RobustMethod::ransac);
  CHECK(error_of([&] { (void)vmap::stack_of({.descriptor = "surf"}, cli); }) ==
        "--features: unknown descriptor 'surf' (choose orb, akaze, sift, xfeat, xfeat-dense or xfeat-star)");
  CHECK(error_of([&] { (void)vmap::stack_of({.method = "foo"}, cli); }) ==
        "--estimator: unknown method 'foo' (choose magsac, ransac, lmeds or 8point)");
  CHECK(error_of([&] { (void)vmap::stack_of({.features = 0}); }) == "nfeatures: must be in [1, 100000], got 0");
  CHECK(error_of([&] { (void)vmap::stack_of({.descriptor = "xfeat"}, cli); }) ==
        "--features xfeat needs --model PATH (an XFeat ONNX export such as xfeat_320x224.onnx)");
  CHECK(error_of([&] { (void)vmap::stack_of({.descriptor = "xfeat-dense"}); }) ==
        "features=xfeat-dense needs model PATH (an XFeat ONNX export such as xfeat_anysize.onnx)");
  CHECK(error_of([&] { (void)vmap::stack_of({.descriptor = "xfeat-star", .model = "m.onnx"}, cli); }) ==
        "--features xfeat-star needs --refine-model PATH (XFeat*'s refinement network, xfeat_fine.onnx)");
  CHECK(error_of([&] { (void)vmap::stack_of({.model = "m.onnx"}); }) ==
        "model: orb takes no model file (only xfeat, xfeat-dense and xfeat-star do)");
  CHECK(error_of([&] { (void)vmap::stack_of({.refine_model = "f.onnx"}); }) ==
        "refine_model: only xfeat-star takes a refinement network");
  // The camera's name in the estimator's errors.
  vmap::PolicyStack calibrated;
  CHECK(vmap::camera_name(calibrated, cli) == "camera");
  calibrated.camera_source = "tum.yaml";
  CHECK(vmap::camera_name(calibrated, cli) == "--camera tum.yaml");
  CHECK(vmap::camera_name(calibrated, OptionNames::keywords()) == "camera=tum.yaml");
  // A calibration from a bag's CameraInfo came from no option: its topic is named.
  calibrated.camera_source = vmap::bag_camera_source("runs/a.db3", "/cam/camera_info");
  CHECK(calibrated.camera_source == "runs/a.db3:/cam/camera_info");
  for (const auto& names : {cli, OptionNames::keywords()})
    CHECK(vmap::camera_name(calibrated, names) == "the CameraInfo of bag 'runs/a.db3', topic '/cam/camera_info'");
  // Files whose names hold ':' stay files.
  for (const char* file : {"cal:/tum.yaml", "/data/run:1/cam.yaml", "x:", ":/cam"}) {
    CAPTURE(file);
    CHECK_FALSE(vmap::parse_bag_camera_source(file));
  }
  calibrated.camera_source = "cal:/tum.yaml";
  CHECK(vmap::camera_name(calibrated, cli) == "--camera cal:/tum.yaml");
}

TEST_CASE("frame range: an empty range or a zero stride is refused before any frame") {
  CHECK(error_of([] { vmap::FrameRange{.start = 10, .end = 5}.validate(OptionNames::command_line()); }) ==
        "--end: must be > --start (10), got 5");
  CHECK(error_of([] { vmap::FrameRange{.start = 3, .end = 3}.validate(); }) == "end: must be > start (3), got 3");
  CHECK(error_of([] { vmap::FrameRange{.stride = 0}.validate(); }) == "stride: must be >= 1");
  const auto o = vmap::FrameRange{.start = 2, .end = 9, .stride = 3}.apply({.grey = true});
  CHECK(o.start == 2);
  CHECK(o.end == 9);
  CHECK(o.stride == 3);
  CHECK(o.grey);
  CHECK(vmap::FrameRange{}.apply({}).end == vmap::FrameSourceOptions{}.end);
}

TEST_CASE("vocabulary to learn: the branching rule and its bounds") {
  // k is the smallest branching with k^depth >= words.
  CHECK(vmap::VocabularyLearning{.words = 1000, .depth = 3}.branching() == 10);
  CHECK(vmap::VocabularyLearning{.words = 1001, .depth = 3}.branching() == 11);
  CHECK(vmap::VocabularyLearning{.words = 2, .depth = 1}.branching() == 2);
  CHECK(vmap::VocabularyLearning{.words = 10000, .depth = 4}.branching() == 10);
  CHECK(vmap::VocabularyLearning{.words = 4096, .depth = 1}.branching() == 4096);
  CHECK(error_of([] { vmap::VocabularyLearning{.words = 4096, .depth = 1}.validate(); }) == "no error");
  CHECK(error_of([] { vmap::VocabularyLearning{.words = 4097, .depth = 1}.validate(); }) ==
        "words=4097 with depth=1 needs a branching above 4096; raise depth or lower words");
  CHECK(error_of([] { vmap::VocabularyLearning{.words = 100000000, .depth = 2}.validate(OptionNames::command_line()); }) ==
        "--words 100000000 with --depth 2 needs a branching above 4096; raise --depth or lower --words");
  CHECK(error_of([] { vmap::VocabularyLearning{.depth = 0}.validate(); }) == "depth: must be in [1, 16], got 0");
  CHECK(error_of([] { vmap::VocabularyLearning{.words = 1}.validate(); }) == "words: must be in [2, 100000000], got 1");
  // learn_vocabulary checks its options before the frames.
  CHECK(error_of([] { (void)vmap::learn_vocabulary({}, {.depth = 17}); }) == "depth: must be in [1, 16], got 17");
  CHECK(error_of([] { (void)vmap::learn_vocabulary({}, {}); }) == "learn_vocabulary: the frames have no descriptors");
}

TEST_CASE("vocabulary files: the format from the name, float trees only in vmap's") {
  CHECK(vmap::vocabulary_format_of("ORBvoc.txt") == vmap::VocabularyFileFormat::orbslam_text);
  CHECK(vmap::vocabulary_format_of("voc.fbow") == vmap::VocabularyFileFormat::fbow);
  CHECK(vmap::vocabulary_format_of("voc.bin") == vmap::VocabularyFileFormat::vmap);
  CHECK(vmap::to_string(vmap::VocabularyFileFormat::orbslam_text) == "orbslam_text");
  CHECK(vmap::to_string(vmap::BowWeighting::idf_l2) == "idf_l2");
  cv::RNG rng(3);
  cv::Mat floats(64, 8, CV_32F);
  rng.fill(floats, cv::RNG::UNIFORM, 0.0, 1.0);
  vmap::Features f;
  f.descriptors = floats;
  const vmap::AnyVocabulary v = vmap::learn_vocabulary({f}, {.words = 4, .depth = 1, .seed = 1});
  CHECK(v.binary() == nullptr);
  CHECK(error_of([&] { (void)vmap::vocabulary_file_bytes(v, vmap::VocabularyFileFormat::fbow, "v.fbow"); }) ==
        "v.fbow is a float vocabulary; FBoW files hold binary ones");
  CHECK(vmap::vocabulary_file_bytes(v, vmap::VocabularyFileFormat::vmap, "v") == v.serialize());
}
