// Benchmark of the place-recognition layer (include/vmap/place), each figure against a
// baseline measured in the same run:
//  (a) loading a 1M-word binary vocabulary (ORB, 32-byte words, k = 10, L = 6) from
//      vmap's file vs cv::FileStorage reading the same 1M words saved as a cv::Mat (YAML
//      text, and YAML with base64 data); file sizes.
//      The tree is generated, not learned (a learned 1M-word tree needs millions of
//      training descriptors): level-1 centres are real ORB descriptors of rtabmap_loop,
//      each child its parent with 13 random bits (5 %) flipped, seeded; idf learned on
//      the rtabmap_loop frames.
//  (b) transform (bag of words) per image of ORB 1000, through the tree vs assigning
//      each descriptor to its nearest word by a linear scan (the same popcount Hamming
//      distance) over the same
//      words, for the 1M-word tree and for a 10k-word tree learned on real frames.
//  (c) query time over databases of 1,000 and 10,000 images (top 10, L1 score) through
//      the inverted file vs a linear scan scoring every image with bow_score; bytes per
//      image. The 1,000 images are ORB 1000 of real frames (tum_fr1_rpy, kitti07_160,
//      rtabmap_loop, tum_fr3_cabinet_kf); the 10,000 are those frames' descriptors with
//      3 % of their bits flipped (10 seeded variants each), so the vectors are distinct.
//
// All times are CPU time of the benchmark's one thread (the machine may be shared).
//
// usage: bench_place [SHARED_DIR] [SCRATCH_DIR]
#include <vmap/features/orb.hpp>
#include <vmap/io/frame_source.hpp>
#include <vmap/place/bow.hpp>
#include <vmap/place/database.hpp>
#include <vmap/place/vocabulary.hpp>

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

  // ---------------------------------------------------------------- (a) 1M-word load
  std::printf("## (a) loading a 1M-word binary vocabulary (k = 10, L = 6, 32-byte words)\n\n");
  t = clock_type::now();
  auto big = generated_tree(rtab_all, 10, 6, 1);
  big.learn_idf(rtab);
  const double gen_ms = ms_since(t);
  const cv::Mat big_words = big.words();
  const auto voc_path = scratch / "voc_1m.vmapvoc";
  const auto yml_path = scratch / "voc_1m_words.yml";
  const auto b64_path = scratch / "voc_1m_words_base64.yml";
  t = clock_type::now();
  big.save(voc_path);
  const double save_ms = ms_since(t);
  t = clock_type::now();
  {
    cv::FileStorage fs(yml_path.string(), cv::FileStorage::WRITE);
    fs << "words" << big_words;
  }
  const double yml_save_ms = ms_since(t);
  t = clock_type::now();
  {
    cv::FileStorage fs(b64_path.string(), cv::FileStorage::WRITE | cv::FileStorage::WRITE_BASE64);
    fs << "words" << big_words;
  }
  const double b64_save_ms = ms_since(t);

  std::vector<double> ours, yml, b64;
  for (int rep = 0; rep < 3; ++rep) {
    t = clock_type::now();
    const auto back = vmap::BinaryVocabularyTree::load(voc_path);
    ours.push_back(ms_since(t));
    if (back.size() != big.size()) return 1;
    t = clock_type::now();
    {
      cv::FileStorage fs(b64_path.string(), cv::FileStorage::READ);
      cv::Mat w;
      fs["words"] >> w;
      if (w.rows != big_words.rows) return 1;
    }
    b64.push_back(ms_since(t));
    if (rep == 0) {  // the text form is slow: once
      t = clock_type::now();
      cv::FileStorage fs(yml_path.string(), cv::FileStorage::READ);
      cv::Mat w;
      fs["words"] >> w;
      if (w.rows != big_words.rows || cv::norm(w, big_words, cv::NORM_L1) != 0.0) return 1;
      yml.push_back(ms_since(t));
    }
  }
  // where the vmap load time goes: reading the bytes, the CRC over them
  t = clock_type::now();
  const std::string voc_bytes = vmap::detail::read_whole_file(voc_path);
  const double read_ms = ms_since(t);
  t = clock_type::now();
  const std::uint32_t crc = vmap::detail::crc32_fast(std::string_view(voc_bytes).substr(24));
  const double crc_ms = ms_since(t);
  t = clock_type::now();
  const std::uint32_t crc_bytewise = vmap::detail::crc32(std::string_view(voc_bytes).substr(24));
  const double crc_bytewise_ms = ms_since(t);
  if (crc != crc_bytewise) return 1;
  const auto mib = [](const std::filesystem::path& p) { return static_cast<double>(std::filesystem::file_size(p)) / (1024.0 * 1024.0); };
  std::printf("generated in %.0f ms: %zu words, %zu nodes, %.1f MiB in memory\n\n", gen_ms, big.size(), big.nodes(),
              static_cast<double>(big.memory_bytes()) / (1024.0 * 1024.0));
  std::printf("| file | what it holds | size (MiB) | save (ms) | load (ms, median of %zu) | load vs vmap |\n", ours.size());
  std::printf("|---|---|---|---|---|---|\n");
  std::printf("| vmap (VMAPVOCB v1) | whole tree: %zu node centres, links, idf; CRC-checked | %.1f | %.0f | %.0f | 1.0x |\n",
              big.nodes(), mib(voc_path), save_ms, median(ours));
  std::printf("| cv::FileStorage YAML, base64 | the %zu leaf words only | %.1f | %.0f | %.0f | %.1fx slower |\n", big.size(),
              mib(b64_path), b64_save_ms, median(b64), median(b64) / median(ours));
  std::printf("| cv::FileStorage YAML text | the %zu leaf words only | %.1f | %.0f | %.0f (once) | %.1fx slower |\n",
              big.size(), mib(yml_path), yml_save_ms, yml[0], yml[0] / median(ours));
  std::printf("of the vmap load: reading the file %.0f ms, its CRC-32 %.0f ms (slicing-by-8; io/binary.hpp's byte-wise "
              "crc32: %.0f ms)\n\n",
              read_ms, crc_ms, crc_bytewise_ms);

  // ---------------------------------------------------------------- (b) transform
  std::printf("## (b) bag of words per image (ORB 1000, %zu rtabmap_loop frames)\n\n", rtab.size());
  t = clock_type::now();
  std::vector<cv::Mat> training = tum;
  training.insert(training.end(), kitti.begin(), kitti.end());
  const auto learned = vmap::BinaryVocabularyTree::learn(training, {.branching = 10, .depth = 4, .seed = 1});
  const double learn_ms = ms_since(t);
  std::printf("learned tree (k = 10, L = 4) on %zu frames of tum_fr1_rpy + kitti07_160 (%zu descriptors, sample of 200,000): "
              "%zu words in %.1f s\n\n",
              training.size(), static_cast<std::size_t>(stack(training).rows), learned.size(), learn_ms / 1000.0);
  std::printf("| vocabulary | words | tree transform (ms / image) | brute-force nearest word (ms / image) | ratio |\n");
  std::printf("|---|---|---|---|---|\n");
  for (const vmap::BinaryVocabularyTree* voc : {&learned, static_cast<const vmap::BinaryVocabularyTree*>(&big)}) {
    t = clock_type::now();
    std::size_t entries = 0;
    for (const auto& d : rtab) entries += voc->transform(d).size();
    const double tree_ms = ms_since(t) / static_cast<double>(rtab.size());
    // brute force over all words: a few images (it is slow for 1M words)
    const cv::Mat words = voc->words();
    const std::size_t bf_images = voc->size() > 100000 ? 2 : 20;
    t = clock_type::now();
    std::size_t agree = 0, total = 0;
    for (std::size_t i = 0; i < bf_images; ++i) {
      const auto tw = voc->assign(rtab[i]);
      for (int r = 0; r < rtab[i].rows; ++r) {
        const uchar* d = rtab[i].ptr<uchar>(r);
        std::uint32_t best = ~0U;
        int arg = 0;
        for (int w = 0; w < words.rows; ++w) {
          const std::uint32_t h = vmap::HammingTraits::distance(d, words.ptr<uchar>(w), 32);
          if (h < best) {
            best = h;
            arg = w;
          }
        }
        agree += tw[static_cast<std::size_t>(r)] == static_cast<std::uint32_t>(arg);
      }
      total += static_cast<std::size_t>(rtab[i].rows);
    }
    const double bf_ms = ms_since(t) / static_cast<double>(bf_images);
    std::printf("| %s | %zu | %.2f | %.1f | %.0fx faster (tree word = nearest word for %.0f %% of descriptors) |\n",
                voc == &big ? "generated 1M" : "learned 10k", voc->size(), tree_ms, bf_ms, bf_ms / tree_ms,
                100.0 * static_cast<double>(agree) / static_cast<double>(std::max<std::size_t>(1, total)));
    (void)entries;
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
