// vmap.Vocabulary (vocabulary trees: learned, or read from vmap's, ORB-SLAM2/3's, DBoW2's
// and FBoW's files; saved in vmap's, ORB-SLAM2's text or FBoW's format), bags of words
// as {word: weight} dicts or (words, weights) arrays, vmap.bow_score, and
// vmap.PlaceDatabase, the inverted-file database the loop detector ranks places with.

#include "bindings.hpp"

#include <vmap/core/features.hpp>
#include <vmap/io/atomic_file.hpp>
#include <vmap/place/bow.hpp>
#include <vmap/place/database.hpp>
#include <vmap/place/vocabulary.hpp>
#include <vmap/runtime/option_names.hpp>
#include <vmap/runtime/vocabulary.hpp>

#include <pybind11/stl/filesystem.h>

#include <algorithm>
#include <cstdint>
#include <filesystem>
#include <limits>
#include <memory>
#include <optional>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

namespace vmap::python {
namespace {

using Database = PlaceDatabase<std::uint32_t>;
using Match = PlaceMatch<std::uint32_t>;

// ---------------------------------------------------------------------------------------
// Descriptors in: a vmap.Features, or an N x D uint8 (binary) / float32 (float) array.

/// The descriptor matrix of `h` (a Features or an array); `what` names the argument in
/// errors. An array whose rows are contiguous is viewed in place (the caller holds it for
/// the call), any other is copied once. The dtype must be uint8 or float32 and the shape
/// N x D: the vocabulary then checks D and the kind against its own.
cv::Mat descriptor_view(const py::handle& h, const std::string& what) {
  if (py::isinstance<Features>(h)) return h.cast<const Features&>().descriptors;
  if (!py::isinstance<py::array>(h))
    fail(what + ": a " + std::string(py::str(py::type::handle_of(h).attr("__name__"))) +
         "; descriptors are a vmap.Features or an N x D NumPy array (uint8 for binary, float32 for float ones)");
  const auto a = py::reinterpret_borrow<py::array>(h);
  const auto dtype = a.dtype();
  int type = -1;
  if (dtype.is(py::dtype::of<std::uint8_t>())) type = CV_8UC1;
  if (dtype.is(py::dtype::of<float>())) type = CV_32FC1;
  if (type < 0)
    fail(what + ": a " + std::string(py::str(py::handle(dtype))) +
         " array; descriptors are uint8 (binary: ORB, A-KAZE) or float32 (SIFT, XFeat): convert it first, "
         "e.g. .astype(numpy.float32)");
  if (a.ndim() != 2)
    fail(what + ": an array of shape " + std::string(py::str(a.attr("shape"))) +
         "; descriptors are N x D, one row per keypoint (one descriptor: d.reshape(1, -1))");
  const auto rows = a.shape(0);
  const auto cols = a.shape(1);
  if (rows > std::numeric_limits<int>::max() || cols > std::numeric_limits<int>::max())
    fail(what + ": " + std::to_string(rows) + " x " + std::to_string(cols) + " descriptors are more than a cv::Mat holds");
  if (rows == 0 || cols == 0) return cv::Mat(0, static_cast<int>(cols), type);
  const auto item = static_cast<py::ssize_t>(a.itemsize());
  // cv::Mat has a row step but no column step: rows read in place when each row's values
  // are contiguous and the rows do not overlap, copied once otherwise.
  if (a.strides(1) == item && a.strides(0) >= item * cols)
    return cv::Mat(static_cast<int>(rows), static_cast<int>(cols), type, const_cast<void*>(a.data()),
                   static_cast<std::size_t>(a.strides(0)));
  const py::array copy = py::array::ensure(a, py::array::c_style);
  return cv::Mat(static_cast<int>(rows), static_cast<int>(cols), type, const_cast<void*>(copy.data())).clone();
}

/// The matrices of a sequence of descriptor inputs, with the Python objects they view
/// (held while the GIL is released: the sequence could change under another thread).
struct DescriptorSets {
  std::vector<cv::Mat> mats;
  std::vector<py::object> held;
};

DescriptorSets descriptor_sets(const py::handle& h, const std::string& what) {
  // One image's descriptors where a list of them is expected: an array would otherwise
  // be read as a list of 1-D rows, and refused row by row.
  if (py::isinstance<Features>(h) || py::isinstance<py::array>(h) || !py::isinstance<py::sequence>(h))
    fail(what + ": a " + std::string(py::str(py::type::handle_of(h).attr("__name__"))) +
         "; expected a list with the descriptors of each image (vmap.Features or N x D arrays)");
  const auto seq = py::reinterpret_borrow<py::sequence>(h);
  DescriptorSets out;
  const auto n = py::len(seq);
  out.mats.reserve(n);
  out.held.reserve(n);
  for (std::size_t i = 0; i < n; ++i) {
    py::object item = seq[i];
    out.mats.push_back(descriptor_view(item, what + "[" + std::to_string(i) + "]"));
    out.held.push_back(std::move(item));
  }
  return out;
}

// ---------------------------------------------------------------------------------------
// Bags of words out and in: {word: weight}, or (words uint32, weights float64) arrays.

py::dict bow_dict(const BowVector& v) {
  py::dict out;
  // Weights are floats in the library: widened to double exactly, so they round-trip.
  for (const auto& e : v.entries) out[py::int_(e.word)] = py::float_(static_cast<double>(e.weight));
  return out;
}

py::tuple bow_sparse(const BowVector& v) {
  const auto n = static_cast<py::ssize_t>(v.size());
  py::array_t<std::uint32_t> words(n);
  py::array_t<double> weights(n);
  auto w = words.mutable_unchecked<1>();
  auto x = weights.mutable_unchecked<1>();
  for (py::ssize_t i = 0; i < n; ++i) {
    w(i) = v.entries[static_cast<std::size_t>(i)].word;
    x(i) = static_cast<double>(v.entries[static_cast<std::size_t>(i)].weight);
  }
  return py::make_tuple(std::move(words), std::move(weights));
}

/// Sorted by word; a word given twice is refused here (the library would only say the
/// words are not increasing). Weight checks (finite, >= 0) and the vocabulary's range are
/// the library's.
BowVector sorted_bow(std::vector<BowEntry> entries, const std::string& what) {
  std::stable_sort(entries.begin(), entries.end(), [](const BowEntry& a, const BowEntry& b) { return a.word < b.word; });
  for (std::size_t i = 1; i < entries.size(); ++i)
    if (entries[i].word == entries[i - 1].word) fail(what + ": word " + std::to_string(entries[i].word) + " is given twice");
  return BowVector{std::move(entries)};
}

std::uint32_t word_id(long long w, const std::string& what) {
  if (w < 0 || w > static_cast<long long>(std::numeric_limits<std::uint32_t>::max()))
    fail(what + ": word id " + std::to_string(w) + " is not in 0..2^32-1");
  return static_cast<std::uint32_t>(w);
}

BowVector bow_from_dict(const py::dict& d, const std::string& what) {
  std::vector<BowEntry> entries;
  entries.reserve(d.size());
  for (const auto& [key, value] : d) {
    // operator.index accepts Python and NumPy integers, nothing else (not 1.0, not "1").
    PyObject* index = PyNumber_Index(key.ptr());
    if (index == nullptr) {
      PyErr_Clear();
      fail(what + ": a key of type " + std::string(py::str(py::type::handle_of(key).attr("__name__"))) +
           "; a bag of words maps integer word ids to weights");
    }
    const auto k = py::reinterpret_steal<py::int_>(index);
    const long long w = PyLong_AsLongLong(k.ptr());
    if (w == -1 && PyErr_Occurred() != nullptr) {
      PyErr_Clear();
      fail(what + ": word id " + std::string(py::str(py::handle(k))) + " is not in 0..2^32-1");
    }
    const double weight = PyFloat_AsDouble(value.ptr());
    if (weight == -1.0 && PyErr_Occurred() != nullptr) {
      PyErr_Clear();
      fail(what + ": the weight of word " + std::to_string(w) + " is a " +
           std::string(py::str(py::type::handle_of(value).attr("__name__"))) + ", not a number");
    }
    entries.push_back({word_id(w, what), static_cast<float>(weight)});
  }
  return sorted_bow(std::move(entries), what);
}

BowVector bow_from_arrays(const py::handle& words_h, const py::handle& weights_h, const std::string& what) {
  if (!py::isinstance<py::array>(words_h) || !py::isinstance<py::array>(weights_h))
    fail(what + ": a sparse bag of words is a pair of NumPy arrays (word ids, weights)");
  const auto words_a = py::reinterpret_borrow<py::array>(words_h);
  const auto weights_a = py::reinterpret_borrow<py::array>(weights_h);
  const char wk = words_a.dtype().kind();
  const char xk = weights_a.dtype().kind();
  if (wk != 'i' && wk != 'u')
    fail(what + ": word ids are a " + std::string(py::str(py::handle(words_a.dtype()))) + " array; they must be integers");
  if (xk != 'f' && xk != 'i' && xk != 'u')
    fail(what + ": weights are a " + std::string(py::str(py::handle(weights_a.dtype()))) + " array; they must be numbers");
  if (words_a.ndim() != 1 || weights_a.ndim() != 1 || words_a.shape(0) != weights_a.shape(0))
    fail(what + ": word ids of shape " + std::string(py::str(words_a.attr("shape"))) + " and weights of shape " +
         std::string(py::str(weights_a.attr("shape"))) + "; they must be 1-D and of one length");
  // Unsigned 64-bit ids above 2^63 become negative here and are refused as out of range.
  const auto w = py::array_t<long long, py::array::forcecast>::ensure(words_a);
  const auto x = py::array_t<double, py::array::forcecast>::ensure(weights_a);
  const auto wv = w.unchecked<1>();
  const auto xv = x.unchecked<1>();
  std::vector<BowEntry> entries(static_cast<std::size_t>(w.shape(0)));
  for (py::ssize_t i = 0; i < w.shape(0); ++i)
    entries[static_cast<std::size_t>(i)] = {word_id(wv(i), what), static_cast<float>(xv(i))};
  return sorted_bow(std::move(entries), what);
}

/// A bag of words given as a dict or a (words, weights) pair; nullopt for anything else
/// (descriptors, which the caller may transform).
std::optional<BowVector> bow_input(const py::handle& h, const std::string& what) {
  if (py::isinstance<py::dict>(h)) return bow_from_dict(py::reinterpret_borrow<py::dict>(h), what);
  if (py::isinstance<py::tuple>(h)) {
    const auto t = py::reinterpret_borrow<py::tuple>(h);
    if (t.size() != 2) fail(what + ": a tuple of " + std::to_string(t.size()) + " items; a sparse bag of words is (word ids, weights)");
    return bow_from_arrays(t[0], t[1], what);
  }
  return std::nullopt;
}

BowVector bow_only(const py::handle& h, const std::string& what) {
  auto v = bow_input(h, what);
  if (!v)
    fail(what + ": a " + std::string(py::str(py::type::handle_of(h).attr("__name__"))) +
         "; a bag of words is a {word: weight} dict or a (word ids, weights) pair of arrays");
  return std::move(*v);
}

BowScoring scoring_named(const std::string& s) {
  if (const auto scoring = from_string<BowScoring>(s)) return *scoring;
  fail("scoring must be 'l1', 'l2' or 'cosine', not '" + s + "'");
}

// ---------------------------------------------------------------------------------------
// Vocabularies.

using VocabularyPtr = std::shared_ptr<AnyVocabulary>;

/// A vocabulary from bytes of any format vmap reads from memory (a gzipped DBoW2 YAML is
/// read by OpenCV from its file only).
AnyVocabulary vocabulary_from_bytes(std::string_view bytes) {
  const std::string name = "<bytes>";
  switch (sniff_vocabulary_format(bytes.substr(0, std::min<std::size_t>(bytes.size(), 4096)), name)) {
    case VocabularyFormat::vmap: return AnyVocabulary::deserialize(bytes, "vocabulary bytes");
    case VocabularyFormat::fbow: return import_fbow(bytes, name);
    case VocabularyFormat::orbslam_text: return import_orbslam_text(bytes, name);
    case VocabularyFormat::dbow2_yaml: break;
  }
  if (!bytes.empty() && static_cast<unsigned char>(bytes[0]) == 0x1F)
    fail("gzipped DBoW2 YAML vocabularies are read from their file: use Vocabulary.load(path)");
  return import_dbow2_yaml(bytes, name);
}

std::vector<BowVector> transform_all(const AnyVocabulary& v, const DescriptorSets& sets) {
  std::vector<BowVector> out;
  out.reserve(sets.mats.size());
  py::gil_scoped_release unlocked;
  for (const auto& d : sets.mats) out.push_back(v.transform(d));
  return out;
}

BowVector transform_one(const AnyVocabulary& v, const py::handle& descriptors) {
  const cv::Mat d = descriptor_view(descriptors, "descriptors");
  py::gil_scoped_release unlocked;
  return v.transform(d);
}

py::array word_centres(const AnyVocabulary& v) {
  if (const auto* b = v.binary()) return to_array(b->words());
  return to_array(v.floating()->words());
}

py::array idf_array(const AnyVocabulary& v) {
  const std::vector<float>& idf = v.binary() != nullptr ? v.binary()->idf() : v.floating()->idf();
  py::array_t<float> out(static_cast<py::ssize_t>(idf.size()));
  std::copy(idf.begin(), idf.end(), out.mutable_data());
  return out;
}

std::size_t node_count(const AnyVocabulary& v) {
  return v.binary() != nullptr ? v.binary()->nodes() : v.floating()->nodes();
}

// ---------------------------------------------------------------------------------------
// The place database, with the vocabulary that turns descriptors into its bags of words.

class PyDatabase {
 public:
  PyDatabase(VocabularyPtr vocabulary, std::size_t words, BowScoring scoring)
      : vocabulary_(std::move(vocabulary)), db_(words, scoring) {}
  /// A loaded database: add() continues above its largest id, or from `next` (a pickled
  /// database's, which may be above it after erase).
  PyDatabase(VocabularyPtr vocabulary, Database db, std::uint64_t next = 0)
      : vocabulary_(std::move(vocabulary)), db_(std::move(db)), next_(next) {
    const auto ids = db_.ids();
    if (!ids.empty()) next_ = std::max(next_, std::uint64_t{ids.back()} + 1);
    check_vocabulary();
  }

  /// A bag of words as such, or the vocabulary's bag of the descriptors given.
  BowVector bow_of(const py::handle& h, const std::string& what) const {
    if (auto v = bow_input(h, what)) return std::move(*v);
    if (!vocabulary_)
      fail(what + ": this database has no vocabulary to turn descriptors into a bag of words; pass a bag of words "
                  "({word: weight} or (word ids, weights)) or create it with PlaceDatabase(vocabulary)");
    return transform_one(*vocabulary_, h);
  }

  std::uint32_t add(const py::handle& x, std::optional<std::uint32_t> id) {
    const BowVector bow = bow_of(x, "PlaceDatabase.add");
    if (!id && next_ > std::numeric_limits<std::uint32_t>::max()) fail("PlaceDatabase.add: no id is left above the largest one");
    const std::uint32_t chosen = id.value_or(static_cast<std::uint32_t>(next_));
    db_.add(chosen, bow);
    next_ = std::max(next_, std::uint64_t{chosen} + 1);
    return chosen;
  }

  [[nodiscard]] std::vector<Match> query(const py::handle& x, std::size_t top_k, std::optional<std::vector<std::uint32_t>> only,
                                         std::optional<std::uint32_t> before) const {
    const BowVector bow = bow_of(x, "PlaceDatabase.query");
    return db_.query(bow, top_k, {.only = std::move(only), .before = before});
  }

  [[nodiscard]] const Database& db() const noexcept { return db_; }
  Database& db() noexcept { return db_; }
  [[nodiscard]] const VocabularyPtr& vocabulary() const noexcept { return vocabulary_; }
  [[nodiscard]] std::uint64_t next_id() const noexcept { return next_; }

 private:
  /// A loaded database and the vocabulary it is given must agree, or every query would
  /// be meaningless (a word outside the vocabulary, or another score).
  void check_vocabulary() const {
    if (!vocabulary_) return;
    if (db_.words() != 0 && db_.words() != vocabulary_->size())
      fail("PlaceDatabase: the database was made for a vocabulary of " + std::to_string(db_.words()) +
           " words; this vocabulary has " + std::to_string(vocabulary_->size()));
    if (db_.scoring() != vocabulary_->scoring())
      fail(std::string("PlaceDatabase: the database scores with ") + to_string(db_.scoring()) + "; this vocabulary with " +
           to_string(vocabulary_->scoring()));
  }

  VocabularyPtr vocabulary_;
  Database db_;
  std::uint64_t next_ = 0;  ///< the id add() gives when none is given: above every id so far
};

PyDatabase make_database(VocabularyPtr vocabulary, std::optional<std::size_t> words, std::optional<std::string> scoring) {
  if (vocabulary) {
    if (words || scoring)
      fail("PlaceDatabase: words and scoring come from the vocabulary; give either a vocabulary or words and scoring");
    if (vocabulary->empty()) fail("PlaceDatabase: the vocabulary is empty");
    const std::size_t size = vocabulary->size();
    const BowScoring by = vocabulary->scoring();
    return {std::move(vocabulary), size, by};
  }
  return {nullptr, words.value_or(0), scoring_named(scoring.value_or("l1"))};
}

py::bytes to_py_bytes(const std::string& s) { return {s.data(), s.size()}; }

std::string_view bytes_view(const py::bytes& b) {
  char* data = nullptr;
  py::ssize_t size = 0;
  if (PyBytes_AsStringAndSize(b.ptr(), &data, &size) != 0) throw py::error_already_set();
  return {data, static_cast<std::size_t>(size)};
}

void bind(py::module_& m) {
  py::class_<AnyVocabulary, VocabularyPtr> voc(
      m, "Vocabulary",
      "A vocabulary tree (Nister and Stewenius 2006, in DBoW2's form): descriptors are clustered into `branching`\n"
      "groups, each group again, down to `depth` levels; the leaves are the words. Binary descriptors (uint8: ORB,\n"
      "A-KAZE) make a Hamming / k-majority tree, float ones (float32: SIFT, XFeat) an L2 / k-means tree.\n"
      "Vocabulary.learn makes one, Vocabulary.load reads vmap's files and ORB-SLAM2/3's ORBvoc.txt, DBoW2's YAML\n"
      "(.yml, .yml.gz) and FBoW's binary, with their word ids and weighting, so that transform gives the bag of\n"
      "words the writing library gives. Read-only: any number of threads may use one at once.");

  voc.def_static(
         "learn",
         [](const py::object& descriptors, int branching, int depth, int iterations, std::size_t max_descriptors,
            std::uint64_t seed) {
           const DescriptorSets sets = descriptor_sets(descriptors, "descriptors");
           const VocabularyTreeOptions o{.branching = branching,
                                         .depth = depth,
                                         .iterations = iterations,
                                         .max_descriptors = max_descriptors,
                                         .seed = seed};
           py::gil_scoped_release unlocked;
           return std::make_shared<AnyVocabulary>(AnyVocabulary::learn(sets.mats, o));
         },
         py::arg("descriptors"), py::kw_only(), py::arg("branching") = VocabularyTreeOptions{}.branching,
         py::arg("depth") = VocabularyTreeOptions{}.depth, py::arg("iterations") = VocabularyTreeOptions{}.iterations,
         py::arg("max_descriptors") = VocabularyTreeOptions{}.max_descriptors,
         py::arg("seed") = VocabularyTreeOptions{}.seed,
         "Learns the tree from the descriptors of a set of images (a list of vmap.Features or of N x D arrays, all\n"
         "uint8 or all float32, of one width), then the idf of every word from the same images. branching: children\n"
         "per node k (2..4096); depth: levels L (1..64; at most k^L words: a node with fewer sample descriptors than\n"
         "k is not split); iterations: k-means / k-majority rounds per node; max_descriptors: the random sample\n"
         "learned from (bounds the time); seed: the sample and the k-means++ seeding (deterministic for a seed).")
      .def_static(
          "load",
          [](const std::filesystem::path& path) {
            py::gil_scoped_release unlocked;
            return std::make_shared<AnyVocabulary>(AnyVocabulary::load(path));
          },
          py::arg("path"),
          "Reads a vocabulary file of any format vmap knows, told apart by its content: vmap's own (binary or float),\n"
          "ORB-SLAM2/3's ORBvoc.txt, DBoW2's YAML (.yml, .yml.gz) or FBoW's binary. Anything else is a vmap.Error\n"
          "naming the file.")
      .def_static(
          "from_bytes",
          [](const py::bytes& data) {
            const std::string_view bytes = bytes_view(data);
            py::gil_scoped_release unlocked;
            return std::make_shared<AnyVocabulary>(vocabulary_from_bytes(bytes));
          },
          py::arg("data"),
          "A vocabulary from the bytes of a file of any format Vocabulary.load reads, but a gzipped DBoW2 YAML (which\n"
          "is read from its file).")
      .def(
          "save",
          [](const AnyVocabulary& v, const std::filesystem::path& path, const std::optional<std::string>& format) {
            const auto f = format ? std::optional(parse_option<VocabularyFileFormat>(*format, "format", "vocabulary format"))
                                  : std::nullopt;
            py::gil_scoped_release unlocked;
            save_vocabulary(v, path, f);
          },
          py::arg("path"), py::kw_only(), py::arg("format") = py::none(),
          "Writes the vocabulary to `path` atomically (a temporary file renamed over it): format 'vmap' (vmap's own),\n"
          "'orbslam_text' (ORB-SLAM2/3's ORBvoc.txt) or 'fbow' (FBoW's binary; these two hold binary vocabularies\n"
          "only). None: from the name, as `vmap vocabulary convert` does (.txt ORB-SLAM2 text, .fbow FBoW, else vmap).")
      .def(
          "to_bytes",
          [](const AnyVocabulary& v, const std::string& format) {
            const auto f = parse_option<VocabularyFileFormat>(format, "format", "vocabulary format");
            std::string bytes;
            {
              py::gil_scoped_release unlocked;
              bytes = vocabulary_file_bytes(v, f, "the vocabulary");
            }
            return to_py_bytes(bytes);
          },
          py::arg("format") = "vmap", "The bytes save() would write in `format` ('vmap', 'orbslam_text' or 'fbow').")
      .def(
          "transform", [](const AnyVocabulary& v, const py::handle& d) { return bow_dict(transform_one(v, d)); },
          py::arg("descriptors"),
          "The image's bag of words as {word: weight}, words increasing, weighted as `weighting` says: for vmap's\n"
          "own (tf_idf_l1) each descriptor adds its word's idf, words of idf 0 are left out, and the weights are\n"
          "L1-normalised. `descriptors`: a vmap.Features or an N x D array of the vocabulary's kind and width. No\n"
          "descriptors: an empty dict.")
      .def(
          "transform_sparse", [](const AnyVocabulary& v, const py::handle& d) { return bow_sparse(transform_one(v, d)); },
          py::arg("descriptors"),
          "transform's bag of words as two arrays: word ids (uint32, increasing) and their weights (float64; the\n"
          "library's float weights, exactly).")
      .def(
          "transform_many",
          [](const AnyVocabulary& v, const py::object& descriptor_sets_in, bool sparse) {
            const DescriptorSets sets = descriptor_sets(descriptor_sets_in, "descriptor_sets");
            const std::vector<BowVector> bows = transform_all(v, sets);
            py::list out;
            for (const auto& b : bows) out.append(sparse ? py::object(bow_sparse(b)) : py::object(bow_dict(b)));
            return out;
          },
          py::arg("descriptor_sets"), py::kw_only(), py::arg("sparse") = false,
          "transform of each item of a list (vmap.Features or arrays), without the GIL held: dicts, or (words,\n"
          "weights) pairs when sparse.")
      .def(
          "assign",
          [](const AnyVocabulary& v, const py::handle& d) {
            const cv::Mat mat = descriptor_view(d, "descriptors");
            std::vector<std::uint32_t> words;
            {
              py::gil_scoped_release unlocked;
              words = v.assign(mat);
            }
            py::array_t<std::uint32_t> out(static_cast<py::ssize_t>(words.size()));
            std::copy(words.begin(), words.end(), out.mutable_data());
            return out;
          },
          py::arg("descriptors"), "The word of each descriptor row (uint32), the leaf its descent from the root reaches.")
      .def(
          "score",
          [](const AnyVocabulary& v, const py::handle& a, const py::handle& b) {
            return bow_score(bow_only(a, "a"), bow_only(b, "b"), v.scoring());
          },
          py::arg("a"), py::arg("b"),
          "Similarity of two bags of words in [0, 1] by this vocabulary's scoring (bow_score with `scoring`).")
      .def_property_readonly("words", &AnyVocabulary::size, "number of words (leaves)")
      .def("__len__", &AnyVocabulary::size)
      .def_property_readonly("branching", &AnyVocabulary::branching, "children per node k")
      .def_property_readonly("depth", &AnyVocabulary::depth, "levels L of the tree")
      .def_property_readonly("nodes", &node_count, "nodes of the tree, the root included")
      .def_property_readonly("binary", [](const AnyVocabulary& v) { return v.binary() != nullptr; },
                             "True for a binary (Hamming) vocabulary, False for a float (L2) one")
      .def_property_readonly("descriptor_dtype",
                             [](const AnyVocabulary& v) {
                               return v.binary() != nullptr ? py::dtype::of<std::uint8_t>() : py::dtype::of<float>();
                             },
                             "dtype of the descriptors it reads: uint8 (binary) or float32")
      .def_property_readonly("descriptor_size", &AnyVocabulary::descriptor_cols,
                             "columns D of a descriptor (bytes for binary, floats for float)")
      .def_property_readonly("norm", [](const AnyVocabulary& v) { return v.binary() != nullptr ? "hamming" : "l2"; },
                             "how descriptors are compared: hamming or l2 (as Features.norm)")
      .def_property_readonly("weighting", [](const AnyVocabulary& v) { return std::string(to_string(v.weighting())); },
                             "how transform weighs and normalises: tf_idf_l1 (vmap), tf_idf_l2, idf_l1, idf_l2 (DBoW2's\n"
                             "other weightings) or fbow (FBoW: summed in float, L2-normalised)")
      .def_property_readonly("scoring", [](const AnyVocabulary& v) { return to_string(v.scoring()); },
                             "the score that goes with the weighting: l1 for L1-normalised bags, l2 for L2 ones")
      .def_property_readonly("idf", &idf_array, "the weight of each word (float32, indexed by word id)")
      .def_property_readonly("word_centres", &word_centres,
                             "the words' centres, row w for word w (words x D, uint8 or float32)")
      .def_property_readonly("memory_bytes", &AnyVocabulary::memory_bytes, "heap bytes held (centres, tree links, idf)")
      .def(py::pickle([](const AnyVocabulary& v) { return to_py_bytes(v.serialize()); },
                      [](const py::bytes& b) {
                        return std::make_shared<AnyVocabulary>(AnyVocabulary::deserialize(bytes_view(b), "pickled vocabulary"));
                      }))
      .def("__repr__", [](const AnyVocabulary& v) {
        return "<vmap.Vocabulary " + std::to_string(v.size()) + " words (branching " + std::to_string(v.branching()) +
               ", depth " + std::to_string(v.depth()) + "), " + (v.binary() != nullptr ? "binary" : "float") + " x " +
               std::to_string(v.descriptor_cols()) + ", " + std::string(to_string(v.weighting())) + ">";
      });

  m.def(
      "bow_score",
      [](const py::handle& a, const py::handle& b, const std::string& scoring) {
        return bow_score(bow_only(a, "a"), bow_only(b, "b"), scoring_named(scoring));
      },
      py::arg("a"), py::arg("b"), py::arg("scoring") = "l1",
      "Similarity of two bags of words ({word: weight} or (word ids, weights)), each normalised here by the\n"
      "scoring's norm: 'l1' (DBoW2's 1 - 0.5 |v - w|_1), 'l2' (DBoW2's 1 - sqrt(1 - <v, w>)) or 'cosine'. In [0, 1]:\n"
      "1 for equal directions, 0 for bags that share no word (or an empty one).");

  py::class_<Match>(m, "PlaceMatch", "One result of PlaceDatabase.query: an entry's id and its score; unpacks as (id, score).")
      .def_readonly("id", &Match::id, "the entry's id (as add() gave it)")
      .def_readonly("score", &Match::score, "in (0, 1], of the database's scoring")
      .def("__iter__", [](const Match& r) { return py::iter(py::make_tuple(r.id, r.score)); })
      .def("__eq__", [](const Match& a, const Match& b) { return a == b; }, py::is_operator())
      .def("__repr__", [](const Match& r) {
        return "PlaceMatch(id=" + std::to_string(r.id) + ", score=" + std::string(py::str(py::float_(r.score))) + ")";
      });

  py::class_<PyDatabase>(
      m, "PlaceDatabase",
      "An inverted-file database of bags of words (DBoW2's Database, T-RO 2012 sec. IV): for every word, the entries\n"
      "in which it occurs and its weight there. A query walks the lists of its own words only and accumulates each\n"
      "entry's score from the shared words. Bags are stored normalised by the scoring's norm. Entries are bags of\n"
      "words ({word: weight} or (word ids, weights)) or, with a vocabulary, descriptors (vmap.Features or arrays).")
      .def(py::init(&make_database), py::arg("vocabulary") = py::none(), py::kw_only(), py::arg("words") = py::none(),
           py::arg("scoring") = py::none(),
           "Over a vocabulary (its size and scoring; descriptors given to add and query are transformed by it), or,\n"
           "without one, for `words` word ids (0, the default, accepts any) scored by `scoring` ('l1', the default,\n"
           "'l2' or 'cosine').")
      .def("add", &PyDatabase::add, py::arg("entry"), py::kw_only(), py::arg("id") = py::none(),
           "Adds an entry (a bag of words, or descriptors with a vocabulary) and returns its id: `id` when given, else\n"
           "one above the largest id added so far (0 first). A duplicate id, or an invalid bag (a word outside the\n"
           "vocabulary, a negative or non-finite weight) is a vmap.Error. An empty bag is stored and never returned.")
      .def("query", &PyDatabase::query, py::arg("entry"), py::arg("top_k") = 10, py::kw_only(), py::arg("only") = py::none(),
           py::arg("before") = py::none(),
           "The `top_k` entries of highest score among those sharing a word with `entry` (a bag of words, or\n"
           "descriptors with a vocabulary), best first, equal scores by increasing id, as PlaceMatch (id, score).\n"
           "only: the ids that are candidates (others ignored); before: only ids < this are candidates (the most\n"
           "recent frames, from `before` on, are trivially similar to the query).")
      .def("erase", [](PyDatabase& d, std::uint32_t id) { return d.db().erase(id); }, py::arg("id"),
           "Removes an entry; False if it was not there.")
      .def("clear", [](PyDatabase& d) { d.db().clear(); }, "Removes every entry.")
      .def("__len__", [](const PyDatabase& d) { return d.db().size(); })
      .def_property_readonly("size", [](const PyDatabase& d) { return d.db().size(); }, "entries held")
      .def("__contains__", [](const PyDatabase& d, std::uint32_t id) { return d.db().contains(id); }, py::arg("id"))
      .def_property_readonly("ids", [](const PyDatabase& d) { return d.db().ids(); }, "the ids, increasing")
      .def(
          "bow",
          [](const PyDatabase& d, std::uint32_t id) -> py::object {
            const BowVector* v = d.db().bow(id);
            return v == nullptr ? py::object(py::none()) : py::object(bow_dict(*v));
          },
          py::arg("id"), "The stored (normalised) bag of words of an entry as {word: weight}, or None.")
      .def_property_readonly("words", [](const PyDatabase& d) { return d.db().words(); },
                             "the vocabulary size word ids are checked against (0: unchecked)")
      .def_property_readonly("scoring", [](const PyDatabase& d) { return to_string(d.db().scoring()); },
                             "l1, l2 or cosine")
      .def_property_readonly("vocabulary", [](const PyDatabase& d) { return d.vocabulary(); },
                             "the Vocabulary descriptors are transformed by, or None")
      .def_property_readonly("memory_bytes", [](const PyDatabase& d) { return d.db().memory_bytes(); },
                             "heap bytes held: posting lists, stored bags, slots and the id index")
      .def(
          "save",
          [](const PyDatabase& d, const std::filesystem::path& path) {
            py::gil_scoped_release unlocked;
            d.db().save(path);
          },
          py::arg("path"), "Writes the database to `path` atomically (vmap's place database file).")
      .def_static(
          "load",
          [](const std::filesystem::path& path, VocabularyPtr vocabulary) {
            std::optional<Database> db;
            {
              py::gil_scoped_release unlocked;
              db.emplace(Database::load(path));
            }
            return PyDatabase(std::move(vocabulary), std::move(*db));
          },
          py::arg("path"), py::kw_only(), py::arg("vocabulary") = py::none(),
          "Reads a database written by save(); anything else is a vmap.Error naming the file. With a vocabulary\n"
          "(which must have the database's size and scoring) descriptors can be added and queried.")
      .def("to_bytes", [](const PyDatabase& d) { return to_py_bytes(d.db().serialize()); },
           "The bytes save() writes.")
      .def_static(
          "from_bytes",
          [](const py::bytes& data, VocabularyPtr vocabulary) {
            return PyDatabase(std::move(vocabulary), Database::deserialize(bytes_view(data), "<bytes>"));
          },
          py::arg("data"), py::kw_only(), py::arg("vocabulary") = py::none(), "A database from to_bytes()'s bytes.")
      .def(py::pickle(
          [](const PyDatabase& d) {
            return py::make_tuple(to_py_bytes(d.db().serialize()), d.vocabulary(), d.next_id());
          },
          [](const py::tuple& t) {
            if (t.size() != 3) fail("PlaceDatabase: not a pickled database");
            return PyDatabase(t[1].cast<VocabularyPtr>(), Database::deserialize(bytes_view(t[0].cast<py::bytes>()), "pickled database"),
                              t[2].cast<std::uint64_t>());
          }))
      .def("__repr__", [](const PyDatabase& d) {
        return "<vmap.PlaceDatabase " + std::to_string(d.db().size()) + " entries, " + to_string(d.db().scoring()) +
               (d.vocabulary() ? ", with a vocabulary of " + std::to_string(d.vocabulary()->size()) + " words>" : ">");
      });
}

const RegisterPart part{order_place, &bind};

}  // namespace
}  // namespace vmap::python
