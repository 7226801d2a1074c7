// Benchmark of the place-recognition layer (include/vmap/place), each figure against a
// baseline measured in the same run:
//  (a) loading a 1M-word binary vocabulary (ORB, 32-byte words, k = 10, L = 6): vmap's
//      file against FBoW's (rmsalinas/fbow, ../shared/baselines/fbow, built beside this
//      program with its own -O3 -mavx2) readFromFile of the same tree in FBoW's format,
//      and vmap's importers of that FBoW file and of the same tree in ORB-SLAM2's
//      ORBvoc.txt text format (both written by place/vocabulary_import.hpp's writers);
//      the same for a 10k-word vocabulary. File sizes.
//      The 1M tree is generated, not learned (a learned 1M-word tree needs millions of
//      training descriptors): level-1 centres are real ORB descriptors of rtabmap_loop,
//      each child its parent with 13 random bits (5 %) flipped, seeded; idf learned on
//      the rtabmap_loop frames. The 10k tree is learned (k = 10, L = 4) on tum_fr1_rpy +
//      kitti07_160.
//  (b) transform (bag of words) per image of ORB 1000 (rtabmap_loop frames): vmap's
//      against FBoW's transform on the same tree and the same descriptors, checking that
//      both give the same words, and that vmap reading the FBoW file gives FBoW's
//      vectors exactly; and against assigning each descriptor to its nearest word by a
//      linear scan.
//  (c) query time over databases of 1,000 and 10,000 images (top 10, L1 score) through
//      the inverted file vs a linear scan scoring every image with bow_score; bytes per
//      image. The 1,000 images are ORB 1000 of real frames (tum_fr1_rpy, kitti07_160,
//      rtabmap_loop, tum_fr3_cabinet_kf); the 10,000 are those frames' descriptors with
//      3 % of their bits flipped (10 seeded variants each), so the vectors are distinct.
//
// All times are CPU time of the benchmark's one thread (the machine may be shared);
// loads are medians of repeated runs with the file in the page cache.
//
// usage: bench_place [SHARED_DIR] [SCRATCH_DIR]
#include <vmap/features/orb.hpp>
#include <vmap/io/frame_source.hpp>
#include <vmap/place/bow.hpp>
#include <vmap/place/database.hpp>
#include <vmap/place/vocabulary.hpp>

#ifdef VMAP_BASELINE_FBOW
#include <fbow.h>
#endif

#include <opencv2/core.hpp>
#include <opencv2/features2d.hpp>

#include <algorithm>
#include <ctime>
#include <cstdio>
#include <filesystem>
#include <random>
#include <string>
#include <vector>

namespace {

// CPU time of this thread: the benchmark machine is shared (other builds run beside it),
// and wall-clock time would count the time this process waits for a core.
struct clock_type {
  using time_point = double;  // ms
  static time_point now() {
    timespec ts{};
    clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
    return static_cast<double>(ts.tv_sec) * 1e3 + static_cast<double>(ts.tv_nsec) * 1e-6;
  }
};
double ms_since(clock_type::time_point t) { return clock_type::now() - t; }

double median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  return v[v.size() / 2];
}

std::vector<cv::Mat> orb_of(const std::filesystem::path& input, std::size_t stride) {
  vmap::OrbDescriptor orb({.features = 1000});
  std::vector<cv::Mat> out;
  auto source = vmap::FrameSource::open(input, {.stride = stride, .grey = true});
  while (auto f = source.next()) out.push_back(orb.extract(f->image).descriptors);
  return out;
}

cv::Mat stack(const std::vector<cv::Mat>& sets) {
  cv::Mat all;
  for (const auto& d : sets)
    if (!d.empty()) all.push_back(d);
  return all;
}

void flip_bits(uchar* row, int cols, int flips, std::mt19937_64& rng) {
  for (int f = 0; f < flips; ++f) {
    const auto bit = static_cast<int>(rng() % static_cast<std::uint64_t>(cols * 8));
    row[bit / 8] = static_cast<uchar>(row[bit / 8] ^ (1U << (bit % 8)));
  }
}

/// The generated full tree (see the header comment).
vmap::BinaryVocabularyTree generated_tree(const cv::Mat& real, int k, int depth, std::uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::vector<std::uint32_t> counts;
  std::size_t level_nodes = 1, total = 0;
  for (int l = 0; l <= depth; ++l) {
    total += level_nodes;
    level_nodes *= static_cast<std::size_t>(k);
  }
  counts.reserve(total);
  cv::Mat centres(static_cast<int>(total), 32, CV_8UC1, cv::Scalar(0));
  // breadth-first: node i's children are k consecutive nodes; a node at level < depth has k
  std::size_t next = 1;
  std::vector<int> level(total, 0);
  for (std::size_t i = 0; i < total; ++i) {
    if (level[i] == depth) {
      counts.push_back(0);
      continue;
    }
    counts.push_back(static_cast<std::uint32_t>(k));
    for (int c = 0; c < k; ++c, ++next) {
      level[next] = level[i] + 1;
      uchar* row = centres.ptr<uchar>(static_cast<int>(next));
      if (i == 0) {
        real.row(static_cast<int>(rng() % static_cast<std::uint64_t>(real.rows))).copyTo(centres.row(static_cast<int>(next)));
      } else {
        std::copy(centres.ptr<uchar>(static_cast<int>(i)), centres.ptr<uchar>(static_cast<int>(i)) + 32, row);
        flip_bits(row, 32, 13, rng);
      }
    }
  }
  std::vector<float> idf(static_cast<std::size_t>(std::count(counts.begin(), counts.end(), 0U)), 1.0f);
  return vmap::BinaryVocabularyTree::from_tree(k, depth, std::move(counts), centres, std::move(idf));
}

}  // namespace

int main(int argc, char** argv) {
  std::setvbuf(stdout, nullptr, _IOLBF, 0);  // the table appears as it is measured
  const std::filesystem::path shared = argc > 1 ? argv[1] : VMAP_SHARED_DIR;
  const std::filesystem::path scratch =
      argc > 2 ? std::filesystem::path(argv[2]) : std::filesystem::temp_directory_path() / "vmap_bench_place";
  std::filesystem::create_directories(scratch);
  const auto data = shared / "data";

  std::fprintf(stderr, "extracting ORB 1000 from the shared frames...\n");
  auto t = clock_type::now();
  const auto rtab = orb_of(data / "rtabmap_loop/images", 1);
  const auto tum = orb_of(data / "tum_fr1_rpy/rgb", 1);
  const auto kitti = orb_of(data / "kitti07_160/image_0", 1);
  const auto cabinet = orb_of(data / "tum_fr3_cabinet_kf/rgb", 1);
  std::fprintf(stderr, "  %zu + %zu + %zu + %zu frames in %.1f s\n", rtab.size(), tum.size(), kitti.size(), cabinet.size(),
               ms_since(t) / 1000.0);
  std::vector<cv::Mat> frames;
  for (const auto* s : {&tum, &kitti, &rtab, &cabinet}) frames.insert(frames.end(), s->begin(), s->end());
  if (frames.size() > 1000) frames.resize(1000);
  const cv::Mat rtab_all = stack(rtab);

  // ---------------------------------------------------------------- (a) load
  t = clock_type::now();
  auto big = generated_tree(rtab_all, 10, 6, 1);
  big.learn_idf(rtab);
  const double gen_ms = ms_since(t);
  t = clock_type::now();
  std::vector<cv::Mat> training = tum;
  training.insert(training.end(), kitti.begin(), kitti.end());
  const auto learned = vmap::BinaryVocabularyTree::learn(training, {.branching = 10, .depth = 4, .seed = 1});
  const double learn_ms = ms_since(t);
  std::printf("## (a) loading a vocabulary: vmap against FBoW on the same tree\n\n");
  std::printf("generated 1M tree (k = 10, L = 6): %zu words, %zu nodes, %.1f MiB in memory, in %.0f ms; learned 10k tree "
              "(k = 10, L = 4) on %zu frames of tum_fr1_rpy + kitti07_160: %zu words in %.1f s\n\n",
              big.size(), big.nodes(), static_cast<double>(big.memory_bytes()) / (1024.0 * 1024.0), gen_ms, training.size(),
              learned.size(), learn_ms / 1000.0);
  const auto mib = [](const std::filesystem::path& p) { return static_cast<double>(std::filesystem::file_size(p)) / (1024.0 * 1024.0); };
  const auto warm = [](const std::filesystem::path& p) { (void)vmap::detail::read_whole_file(p); };  // into the page cache
  struct Voc {
    const char* name;
    const vmap::BinaryVocabularyTree* tree;
    std::string stem;
  };
  std::printf("| vocabulary | loader | file | size (MiB) | load (ms, median) | vs FBoW's load |\n|---|---|---|---|---|---|\n");
  for (const Voc& voc : {Voc{"generated 1M", &big, "voc_1m"}, Voc{"learned 10k", &learned, "voc_10k"}}) {
    const auto vmap_path = scratch / (voc.stem + ".vmapvoc");
    const auto fbow_path = scratch / (voc.stem + ".fbow");
    const auto text_path = scratch / (voc.stem + "_orbvoc.txt");
    voc.tree->save(vmap_path);
    vmap::write_file_atomically(fbow_path, vmap::fbow_bytes(*voc.tree));
    vmap::write_file_atomically(text_path, vmap::orbslam_text(*voc.tree));
    const int reps = voc.tree->size() > 100000 ? 7 : 21;
    std::vector<double> ours, theirs, imported_fbow, imported_text;
    for (int rep = 0; rep < reps; ++rep) {
      warm(vmap_path);
      t = clock_type::now();
      const auto back = vmap::BinaryVocabularyTree::load(vmap_path);
      ours.push_back(ms_since(t));
      if (back.size() != voc.tree->size()) return 1;
#ifdef VMAP_BASELINE_FBOW
      warm(fbow_path);
      t = clock_type::now();
      fbow::Vocabulary fv;
      fv.readFromFile(fbow_path.string());
      theirs.push_back(ms_since(t));
      if (!fv.isValid()) return 1;
#endif
      if (rep < 3) {
        warm(fbow_path);
        t = clock_type::now();
        const auto f = vmap::AnyVocabulary::load(fbow_path);
        imported_fbow.push_back(ms_since(t));
        if (f.size() != voc.tree->size()) return 1;
      }
      if (rep < (voc.tree->size() > 100000 ? 1 : 3)) {
        warm(text_path);
        t = clock_type::now();
        const auto x = vmap::AnyVocabulary::load(text_path);
        imported_text.push_back(ms_since(t));
        if (x.size() != voc.tree->size()) return 1;
      }
    }
    const double base = theirs.empty() ? 0.0 : median(theirs);
    auto row = [&](const char* loader, const std::filesystem::path& p, const std::vector<double>& ms) {
      const double m = median(ms);
      std::printf("| %s | %s | %s | %.1f | %.3f | %s |\n", voc.name, loader, p.filename().c_str(), mib(p), m,
                  base > 0.0 ? (std::to_string(m / base).substr(0, 5) + "x").c_str() : "(FBoW not built)");
    };
    if (!theirs.empty()) row("FBoW readFromFile (baseline)", fbow_path, theirs);
    row("vmap load (format 2, CRC-32C checked)", vmap_path, ours);
    row("vmap AnyVocabulary::load of FBoW's file", fbow_path, imported_fbow);
    row("vmap AnyVocabulary::load of ORBvoc.txt text", text_path, imported_text);
  }
  {
    const std::string bytes = vmap::detail::read_whole_file(scratch / "voc_1m.vmapvoc");
    const std::string_view payload = std::string_view(bytes).substr(24);
    t = clock_type::now();
    const std::uint32_t c1 = vmap::detail::crc32c(payload);
    const double hw = ms_since(t);
    t = clock_type::now();
    const std::uint32_t c2 = vmap::detail::crc32c(payload, true);
    const double portable = ms_since(t);
    t = clock_type::now();
    const std::uint32_t c3 = vmap::detail::crc32_fast(payload);
    const double old_crc = ms_since(t);
    if (c1 != c2 || c3 == 0) return 1;
    std::printf("\nchecksum of the 1M file's %.1f MiB: CRC-32C %.1f ms (%s), portable CRC-32C %.1f ms, format 1's CRC-32 "
                "(slicing-by-8) %.1f ms\n\n",
                static_cast<double>(payload.size()) / (1024.0 * 1024.0), hw,
                vmap::detail::crc32c_hardware_available() ? "SSE 4.2 instruction" : "no hardware CRC: portable", portable, old_crc);
  }

  // ---------------------------------------------------------------- (b) transform
  std::vector<cv::Mat> images;  // FBoW's transform refuses an image without descriptors
  for (const auto& d : rtab)
    if (!d.empty()) images.push_back(d);
  std::printf("## (b) bag of words per image (ORB 1000, the %zu of %zu rtabmap_loop frames with descriptors)\n\n", images.size(),
              rtab.size());
  std::printf("| vocabulary | words | vmap transform (ms / image) | FBoW transform (ms / image) | vmap vs FBoW | same words as FBoW | "
              "vmap on FBoW's file = FBoW's vectors | brute-force nearest word (ms / image) |\n|---|---|---|---|---|---|---|---|\n");
  for (const Voc& voc : {Voc{"learned 10k", &learned, "voc_10k"}, Voc{"generated 1M", &big, "voc_1m"}}) {
    // each library's tree as loaded from its file, as a user has it
    const auto loaded = vmap::BinaryVocabularyTree::load(scratch / (voc.stem + ".vmapvoc"));
    const auto& tree = loaded;
    std::vector<double> ours, theirs;
    std::size_t same_words = 0, same_vectors = 0, total_rows = 0;
    const auto from_fbow = vmap::AnyVocabulary::load(scratch / (voc.stem + ".fbow"));
#ifdef VMAP_BASELINE_FBOW
    fbow::Vocabulary fv;
    fv.readFromFile((scratch / (voc.stem + ".fbow")).string());
#endif
    for (int rep = 0; rep < 3; ++rep) {
      std::size_t entries = 0;
      t = clock_type::now();
      for (const auto& d : images) entries += tree.transform(d).size();
      ours.push_back(ms_since(t) / static_cast<double>(images.size()));
#ifdef VMAP_BASELINE_FBOW
      std::size_t their_entries = 0;
      t = clock_type::now();
      for (const auto& d : images) their_entries += fv.transform(d).size();
      theirs.push_back(ms_since(t) / static_cast<double>(images.size()));
      if (their_entries == 0) return 1;
#endif
      if (entries == 0) return 1;
    }
#ifdef VMAP_BASELINE_FBOW
    for (const auto& d : images) {
      const vmap::BowVector mine = tree.transform(d);
      const fbow::fBow theirs_bow = fv.transform(d);
      bool words_equal = mine.size() == theirs_bow.size();
      vmap::BowVector as_vmap;
      for (const auto& [word, weight] : theirs_bow) as_vmap.entries.push_back({word, static_cast<float>(weight)});
      for (std::size_t i = 0; words_equal && i < mine.size(); ++i) words_equal = mine.entries[i].word == as_vmap.entries[i].word;
      same_words += words_equal;
      same_vectors += from_fbow.transform(d) == as_vmap;
      ++total_rows;
    }
#endif
    // brute force over all words: a few images (it is slow for 1M words)
    const cv::Mat words = tree.words();
    const std::size_t bf_images = tree.size() > 100000 ? 2 : 20;
    t = clock_type::now();
    std::uint64_t nearest_sum = 0;  // used, so the scan is not optimised away
    for (std::size_t i = 0; i < bf_images; ++i)
      for (int r = 0; r < images[i].rows; ++r) {
        const uchar* d = images[i].ptr<uchar>(r);
        std::uint32_t best = ~0U, arg = 0;
        for (int w = 0; w < words.rows; ++w) {
          const std::uint32_t h = vmap::HammingTraits::distance(d, words.ptr<uchar>(w), 32);
          if (h < best) {
            best = h;
            arg = static_cast<std::uint32_t>(w);
          }
        }
        nearest_sum += arg;
      }
    if (nearest_sum == 0) return 1;
    const double bf_ms = ms_since(t) / static_cast<double>(bf_images);
    const double m = median(ours);
    const double f = theirs.empty() ? 0.0 : median(theirs);
    std::printf("| %s | %zu | %.3f | %.3f | %.2fx | %zu / %zu images | %zu / %zu images | %.1f |\n", voc.name, tree.size(), m, f,
                f > 0.0 ? m / f : 0.0, same_words, total_rows, same_vectors, total_rows, bf_ms);
  }
  std::printf("\n");

  // ---------------------------------------------------------------- (c) query
  std::printf("## (c) query (top 10, L1) through the inverted file vs a linear scan\n\n");
  std::printf("| vocabulary | images | inverted file (ms / query) | linear scan (ms / query) | ratio | bytes / image | db save / load (ms) |\n");
  std::printf("|---|---|---|---|---|---|---|\n");
  for (const vmap::BinaryVocabularyTree* voc : {&learned, static_cast<const vmap::BinaryVocabularyTree*>(&big)}) {
    std::vector<vmap::BowVector> bows;
    bows.reserve(10000);
    for (const auto& d : frames) bows.push_back(voc->transform(d));
    std::mt19937_64 rng(7);
    for (int variant = 1; bows.size() < 10000; ++variant)
      for (const auto& d : frames) {
        if (bows.size() >= 10000) break;
        cv::Mat noisy = d.clone();
        for (int r = 0; r < noisy.rows; ++r) flip_bits(noisy.ptr<uchar>(r), 32, 8, rng);  // 8 of 256 bits: 3 %
        bows.push_back(voc->transform(noisy));
      }
    std::vector<vmap::BowVector> queries;
    for (const auto& d : rtab) queries.push_back(voc->transform(d));
    for (std::size_t n : {1000U, 10000U}) {
      vmap::PlaceDatabase<std::uint32_t> db(voc->size());
      for (std::size_t i = 0; i < n; ++i) db.add(static_cast<std::uint32_t>(i), bows[i]);
      std::size_t checksum = 0;
      for (const auto& q : queries) checksum += db.query(q, 10).size();  // warm the scratch
      t = clock_type::now();
      for (int rep = 0; rep < 3; ++rep)
        for (const auto& q : queries) checksum += db.query(q, 10).size();
      const double inv_ms = ms_since(t) / (3.0 * static_cast<double>(queries.size()));
      t = clock_type::now();
      for (const auto& q : queries) {
        std::vector<std::pair<double, std::size_t>> s;
        s.reserve(n);
        for (std::size_t i = 0; i < n; ++i) s.emplace_back(-vmap::bow_score(q, bows[i]), i);
        std::partial_sort(s.begin(), s.begin() + 10, s.end());
        checksum += s[0].second;
      }
      const double scan_ms = ms_since(t) / static_cast<double>(queries.size());
      const auto db_path = scratch / "db.vmapbow";
      t = clock_type::now();
      db.save(db_path);
      const double dsave = ms_since(t);
      t = clock_type::now();
      const auto back = vmap::PlaceDatabase<std::uint32_t>::load(db_path);
      const double dload = ms_since(t);
      std::printf("| %s | %zu | %.3f | %.2f | %.0fx faster | %.0f | %.0f / %.0f |\n", voc == &big ? "generated 1M" : "learned 10k",
                  n, inv_ms, scan_ms, scan_ms / inv_ms, static_cast<double>(db.memory_bytes()) / static_cast<double>(n), dsave,
                  dload);
      if (back.size() != db.size() || checksum == 0) return 1;
    }
  }
  std::printf("\nmean words per image: learned 10k %.0f\n", [&] {
    double s = 0;
    for (const auto& d : rtab) s += static_cast<double>(learned.transform(d).size());
    return s / static_cast<double>(rtab.size());
  }());
  return 0;
}
