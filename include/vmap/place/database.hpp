#pragma once

// An inverted-file database of bag-of-words vectors (DBoW2's Database, Gálvez-López and
// Tardós, T-RO 2012, sec. IV): for every word, the images in which it occurs and its
// weight there. A query walks the lists of its own words only, so images sharing no word
// with it cost nothing, and accumulates each image's score from the shared words (for
// the L1 score, sum min(q_i, v_i) on L1-normalised vectors, which equals DBoW2's
// 1 - 0.5 |q - v|_1; see bow.hpp).
//
// File format (version 1), io/binary.hpp's encoding:
//   header (24 bytes): u8[8] magic "VMAPBOWD", u32 version, u64 payload size, u32 CRC-32
//   payload:
//     u8   scoring (0 = l1, 1 = l2, 2 = cosine)
//     u64  words (the vocabulary size the word ids are checked against; 0 = unchecked)
//     u64  images n
//     n x  { u64 id (two's complement for signed ids; strictly increasing);
//            u32 entries e; e x { u32 word (strictly increasing), f32 weight } }
//   weights are stored normalised (by the scoring's norm), as the database holds them.

#include <vmap/core/error.hpp>
#include <vmap/io/atomic_file.hpp>
#include <vmap/io/binary.hpp>
#include <vmap/place/bow.hpp>
#include <vmap/place/detail/format.hpp>
#include <vmap/place/match.hpp>

#include <algorithm>
#include <bit>
#include <cmath>
#include <concepts>
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <limits>
#include <map>
#include <optional>
#include <string>
#include <string_view>
#include <type_traits>
#include <utility>
#include <vector>

namespace vmap {

template <class Id = std::uint32_t>
struct QueryFilter {
  /// Only these ids are candidates (e.g. the frames of a label-tree leaf); ids not in
  /// the database are ignored. Unset: every image.
  std::optional<std::vector<Id>> only{};
  /// Only ids < this are candidates: the most recent frames (from `before` on) are
  /// trivially similar to the query. Unset: no bound.
  std::optional<Id> before{};
  /// Only ids >= this are candidates (the frames of the current session). Unset: no bound.
  std::optional<Id> from{};
};

/// Inverted-file place database.
///
/// Costs: `add` O(|bow| + log size); `erase` O(sum of the posting lists of its words);
/// `query` O(sum of the posting lists of the query's words + candidates log top_k), or,
/// with a small `only` set, O(|only| (|q| + |v|)) by scoring those images directly
/// (whichever the lists' lengths say is cheaper; both give the same scores).
///
/// Stored vectors are normalised by the scoring's norm (L1 for l1, L2 for l2 / cosine).
///
/// Thread safety: const members (`query`, `contains`, `bow`, `size`, `memory_bytes`,
/// `save`, ...) only read the database, so any number of threads may call them at once
/// (each query uses scratch memory of its own thread). `add`, `erase` and `clear`
/// modify it and need exclusive access: no other call may run at the same time (guard
/// with a std::shared_mutex, shared for queries and unique for updates, when images are
/// added while other threads query).
template <class Id = std::uint32_t>
  requires std::totally_ordered<Id> && std::copyable<Id>
class PlaceDatabase {
 public:
  /// `words`: the vocabulary size (word ids must be below it); 0 accepts any word id.
  explicit PlaceDatabase(std::size_t words = 0, BowScoring scoring = BowScoring::l1)
      : words_(words), scoring_(scoring) {}

  /// Adds an image. A duplicate id, or an invalid vector (unsorted, a word outside the
  /// vocabulary, a negative or non-finite weight) is an Error. An empty (or all-zero)
  /// vector is stored and never returned by a query.
  void add(Id id, const BowVector& bow) {
    detail::check(!slot_of_.contains(id), "PlaceDatabase::add: the id is already in the database");
    detail::check_bow(bow, words_, "PlaceDatabase::add");
    BowVector v;
    const double norm = detail::scoring_norm(bow, scoring_);
    if (norm > 0.0) {
      v.entries.reserve(bow.size());
      for (const auto& e : bow.entries)
        if (e.weight > 0.0f) v.entries.push_back({e.word, static_cast<float>(e.weight / norm)});
    }
    insert(std::move(id), std::move(v));
  }

  /// Removes an image; false if it was not there.
  bool erase(const Id& id) {
    const auto it = slot_of_.find(id);
    if (it == slot_of_.end()) return false;
    const std::uint32_t slot = it->second;
    for (const auto& e : slots_[slot].bow.entries) {
      auto& list = postings_[e.word];
      for (std::size_t i = 0; i < list.size(); ++i)
        if (list[i].slot == slot) {
          list[i] = list.back();
          list.pop_back();
          break;
        }
    }
    slots_[slot] = Slot{};
    free_.push_back(slot);
    slot_of_.erase(it);
    return true;
  }

  void clear() {
    postings_.clear();
    slots_.clear();
    free_.clear();
    slot_of_.clear();
  }

  /// The `top_k` images of highest score among those sharing a word with `q` and passing
  /// the filter, best first; equal scores by increasing id.
  [[nodiscard]] std::vector<PlaceMatch<Id>> query(const BowVector& q, std::size_t top_k,
                                                  const QueryFilter<Id>& filter = {}) const {
    detail::check_bow(q, words_, "PlaceDatabase::query");
    std::vector<PlaceMatch<Id>> out;
    const double norm = detail::scoring_norm(q, scoring_);
    if (top_k == 0 || norm <= 0.0 || slot_of_.empty()) return out;
    std::vector<BowEntry> qn;
    qn.reserve(q.size());
    std::size_t work = 0;  // posting entries the inverted file would visit
    for (const auto& e : q.entries)
      if (e.weight > 0.0f) {
        qn.push_back({e.word, static_cast<float>(e.weight / norm)});
        if (e.word < postings_.size()) work += postings_[e.word].size();
      }
    // The stored and query weights are floats normalised to within a rounding error; for
    // L2 and cosine the dot product is divided by the norms of those floats, so that a
    // vector scores 1 against itself up to 1e-16 and not 1e-8 (1 - sqrt(1 - dot)
    // would turn 1e-8 into 1e-4).
    const double qnorm = scoring_ == BowScoring::l1 ? 1.0 : BowVector{qn}.l2_norm();
    auto excluded = [&](const Id& id) {
      return (filter.before && !(id < *filter.before)) || (filter.from && id < *filter.from);
    };
    auto keep = [&](std::uint32_t slot, double shared) {
      const Slot& s = slots_[slot];
      if (shared > 0.0 && !excluded(s.id))
        out.push_back({s.id, detail::score_from_shared(scoring_ == BowScoring::l1 ? shared : shared / (qnorm * s.norm), scoring_)});
    };

    if (filter.only) {
      std::vector<std::uint32_t> cand;
      cand.reserve(filter.only->size());
      std::size_t direct_work = 0;
      for (const Id& id : *filter.only) {
        const auto it = slot_of_.find(id);
        if (it == slot_of_.end()) continue;
        cand.push_back(it->second);
        direct_work += qn.size() + slots_[it->second].bow.size();
      }
      std::sort(cand.begin(), cand.end());
      cand.erase(std::unique(cand.begin(), cand.end()), cand.end());  // an id given twice counts once
      if (direct_work <= work) {
        for (std::uint32_t s : cand) keep(s, shared_with(qn, slots_[s].bow));
      } else {
        auto& acc = scratch();
        accumulate(qn, acc);
        for (std::uint32_t s : cand) keep(s, acc.value[s]);
        std::fill_n(acc.value.begin(), slots_.size(), 0.0);
      }
    } else {
      auto& acc = scratch();
      accumulate(qn, acc);
      for (std::uint32_t s = 0; s < slots_.size(); ++s)
        if (acc.value[s] != 0.0) {
          keep(s, acc.value[s]);
          acc.value[s] = 0.0;
        }
    }

    auto better = [](const PlaceMatch<Id>& a, const PlaceMatch<Id>& b) {
      if (a.score != b.score) return a.score > b.score;
      return a.id < b.id;
    };
    if (out.size() > top_k) {
      std::partial_sort(out.begin(), out.begin() + static_cast<std::ptrdiff_t>(top_k), out.end(), better);
      out.resize(top_k);
    } else {
      std::sort(out.begin(), out.end(), better);
    }
    return out;
  }

  [[nodiscard]] bool contains(const Id& id) const { return slot_of_.contains(id); }
  /// The stored (normalised) vector of an image, or nullptr. Valid until the next add,
  /// erase or clear.
  [[nodiscard]] const BowVector* bow(const Id& id) const {
    const auto it = slot_of_.find(id);
    return it == slot_of_.end() ? nullptr : &slots_[it->second].bow;
  }
  /// The ids, increasing.
  [[nodiscard]] std::vector<Id> ids() const {
    std::vector<Id> out;
    out.reserve(slot_of_.size());
    for (const auto& [id, slot] : slot_of_) out.push_back(id);
    return out;
  }
  [[nodiscard]] std::size_t size() const noexcept { return slot_of_.size(); }
  [[nodiscard]] bool empty() const noexcept { return slot_of_.empty(); }
  [[nodiscard]] std::size_t words() const noexcept { return words_; }
  [[nodiscard]] BowScoring scoring() const noexcept { return scoring_; }

  /// Heap bytes held: the posting lists, the stored vectors, the slots and the id index
  /// (its tree nodes counted as the key, the slot and three pointers and a colour word,
  /// as libstdc++ lays them out). Not the per-thread query scratch (8 bytes per slot).
  [[nodiscard]] std::size_t memory_bytes() const noexcept {
    std::size_t b = postings_.capacity() * sizeof(std::vector<Posting>);
    for (const auto& l : postings_) b += l.capacity() * sizeof(Posting);
    b += slots_.capacity() * sizeof(Slot);
    for (const auto& s : slots_) b += s.bow.entries.capacity() * sizeof(BowEntry);
    b += free_.capacity() * sizeof(std::uint32_t);
    b += slot_of_.size() * (sizeof(std::pair<const Id, std::uint32_t>) + 4 * sizeof(void*));
    return b;
  }

  /// The file's bytes (format at the top of this header). Needs integral ids.
  [[nodiscard]] std::string serialize() const
    requires std::integral<Id>
  {
    detail::BinaryWriter w;
    for (const auto& [id, slot] : slot_of_) write_record(w, id, slots_[slot].bow);
    return serialize_records(scoring_, words_, slot_of_.size(), std::move(w).take());
  }

  /// One image's part of the file ("u64 id, u32 e, e x {u32 word, f32 weight}"): a store
  /// that keeps images apart (memory/store.hpp) joins them with serialize_records.
  /// Empty when `id` is not in the database.
  [[nodiscard]] std::string record(const Id& id) const
    requires std::integral<Id>
  {
    const auto it = slot_of_.find(id);
    if (it == slot_of_.end()) return {};
    detail::BinaryWriter w;
    write_record(w, id, slots_[it->second].bow);
    return std::move(w).take();
  }

  /// record() of an image with this vector.
  [[nodiscard]] static std::string record_of(const Id& id, const BowVector& bow)
    requires std::integral<Id>
  {
    detail::BinaryWriter w;
    write_record(w, id, bow);
    return std::move(w).take();
  }

  /// The file's bytes from `count` records (record()) joined in increasing id order.
  [[nodiscard]] static std::string serialize_records(BowScoring scoring, std::size_t words, std::size_t count,
                                                     std::string_view records) {
    detail::BinaryWriter w;
    w.u8(static_cast<std::uint8_t>(scoring));
    w.u64(words);
    w.u64(count);
    w.bytes(records);
    return detail::wrap_payload(file_magic(), file_version, std::move(w).take());
  }

  [[nodiscard]] static PlaceDatabase deserialize(std::string_view bytes, const std::string& name = "<memory>")
    requires std::integral<Id>
  {
    auto r = detail::open_payload(bytes, file_magic(), file_version, "place database", "place database file '" + name + "'");
    const std::uint8_t scoring = r.u8("scoring");
    if (scoring > static_cast<std::uint8_t>(BowScoring::cosine)) r.corrupt("unknown scoring " + std::to_string(scoring));
    const std::uint64_t words = r.u64("words");
    if (words > std::numeric_limits<std::uint32_t>::max()) r.corrupt("vocabulary size " + std::to_string(words) + " is too large");
    const std::uint64_t n = r.u64("image count");
    r.require_items(n, 12, "image count");  // an image takes at least 12 bytes
    std::vector<std::pair<Id, BowVector>> images;
    images.reserve(static_cast<std::size_t>(n));
    for (std::uint64_t i = 0; i < n; ++i) {
      images.push_back(read_record(r, static_cast<std::size_t>(words), static_cast<BowScoring>(scoring)));
      if (i > 0 && !(images[i - 1].first < images[i].first)) r.corrupt("image ids are not strictly increasing");
    }
    r.expect_end("the last image");
    return from_records(static_cast<BowScoring>(scoring), static_cast<std::size_t>(words), std::move(images));
  }

  /// One image's record (record()) read back: its id and vector, checked against a
  /// vocabulary of `words` words and the scoring's normalisation.
  [[nodiscard]] static std::pair<Id, BowVector> read_record(detail::BinaryReader& r, std::size_t words, BowScoring scoring)
    requires std::integral<Id>
  {
    using Wide = std::conditional_t<std::is_signed_v<Id>, std::int64_t, std::uint64_t>;
    const auto wide = static_cast<Wide>(r.u64("image id"));
    const auto id = static_cast<Id>(wide);
    if (static_cast<Wide>(id) != wide) r.corrupt("image id " + std::to_string(wide) + " does not fit the id type");
    const std::uint32_t e = r.u32("entry count");
    r.require_items(e, 8, "entry count");
    BowVector v;
    v.entries.resize(e);
    if constexpr (entries_as_bytes) {
      const auto block = r.bytes(std::uint64_t{e} * sizeof(BowEntry), "entries");
      if (e > 0) std::memcpy(v.entries.data(), block.data(), block.size());  // no null destination
    } else {
      for (auto& x : v.entries) {
        x.word = r.u32("word");
        x.weight = r.f32("weight");
      }
    }
    try {
      detail::check_bow(v, words, "an image's vector");
    } catch (const Error& err) {
      r.corrupt(err.what());
    }
    for (const auto& x : v.entries)
      if (x.weight <= 0.0f) r.corrupt("an image's vector has a zero weight");
    if (!v.empty() && std::fabs(detail::scoring_norm(v, scoring) - 1.0) > 1e-3) r.corrupt("an image's vector is not normalised");
    return {id, std::move(v)};
  }

  /// A database of these images (read_record()'s, in increasing id order) over a
  /// vocabulary of `words` words.
  [[nodiscard]] static PlaceDatabase from_records(BowScoring scoring, std::size_t words,
                                                  std::vector<std::pair<Id, BowVector>> images) {
    PlaceDatabase db(words, scoring);
    // The posting lists sized once from the word counts: no regrowth while loading, and
    // no spare capacity afterwards.
    std::vector<std::uint32_t> per_word;
    for (const auto& [id, v] : images)
      for (const auto& e : v.entries) {
        if (e.word >= per_word.size()) per_word.resize(e.word + std::size_t{1}, 0);
        ++per_word[e.word];
      }
    db.postings_.resize(per_word.size());
    for (std::size_t w = 0; w < per_word.size(); ++w) db.postings_[w].reserve(per_word[w]);
    db.slots_.reserve(images.size());
    for (auto& [id, v] : images) db.insert(id, std::move(v));
    return db;
  }

  /// Writes the database to `path` atomically. Needs integral ids.
  void save(const std::filesystem::path& path) const
    requires std::integral<Id>
  {
    write_file_atomically(path, serialize());
  }

  /// Reads a database written by save(); anything else is a vmap::Error naming the file.
  [[nodiscard]] static PlaceDatabase load(const std::filesystem::path& path)
    requires std::integral<Id>
  {
    return deserialize(detail::read_whole_file(path, "place database file"), path.string());
  }

  static constexpr std::uint32_t file_version = 1;

 private:
  static void write_record(detail::BinaryWriter& w, const Id& id, const BowVector& v) {
    w.u64(static_cast<std::uint64_t>(static_cast<std::conditional_t<std::is_signed_v<Id>, std::int64_t, std::uint64_t>>(id)));
    w.u32(static_cast<std::uint32_t>(v.size()));
    if constexpr (entries_as_bytes) {
      if (!v.empty()) w.bytes(v.entries.data(), v.entries.size() * sizeof(BowEntry));  // {u32 word, f32 weight} as stored
    } else {
      for (const auto& e : v.entries) {
        w.u32(e.word);
        w.f32(e.weight);
      }
    }
  }

 public:
  static constexpr std::string_view file_magic() noexcept { return {"VMAPBOWD", 8}; }

 private:
  /// A BowEntry is laid out as the file's {u32 word, f32 weight} on a little-endian host:
  /// vectors are then copied as blocks.
  static constexpr bool entries_as_bytes = std::endian::native == std::endian::little && sizeof(BowEntry) == 8 &&
                                           offsetof(BowEntry, word) == 0 && offsetof(BowEntry, weight) == 4 &&
                                           std::is_trivially_copyable_v<BowEntry>;

  struct Posting {
    std::uint32_t slot;
    float weight;  ///< normalised
  };
  struct Slot {
    Id id{};
    BowVector bow;      ///< normalised, no zero weights
    double norm = 1.0;  ///< the scoring's norm of `bow` as stored (1 up to float rounding)
  };
  /// Per-thread accumulator over slots, all zero between queries, so a warm query does
  /// not allocate. Images that share no word keep 0 (every shared term is > 0), so the
  /// scored ones are found by one sequential pass over the slots afterwards, which costs
  /// less than tracking them in the hot loop.
  struct Scratch {
    std::vector<double> value;
  };
  static Scratch& scratch() {
    thread_local Scratch s;
    return s;
  }

  /// Sums each image's shared-word terms over the query's posting lists, in the query's
  /// word order (the order shared_with() uses, so both give bit-equal sums).
  void accumulate(const std::vector<BowEntry>& qn, Scratch& acc) const {
    if (acc.value.size() < slots_.size()) acc.value.resize(slots_.size(), 0.0);
    double* value = acc.value.data();
    for (const auto& e : qn) {
      if (e.word >= postings_.size()) continue;
      const double q = e.weight;
      if (scoring_ == BowScoring::l1) {
        for (const auto& p : postings_[e.word]) value[p.slot] += std::min(q, static_cast<double>(p.weight));
      } else {
        for (const auto& p : postings_[e.word]) value[p.slot] += q * static_cast<double>(p.weight);
      }
    }
  }

  double shared_with(const std::vector<BowEntry>& qn, const BowVector& v) const {
    double s = 0.0;
    auto a = qn.begin();
    auto b = v.entries.begin();
    while (a != qn.end() && b != v.entries.end()) {
      if (a->word < b->word) {
        ++a;
      } else if (b->word < a->word) {
        ++b;
      } else {
        s += detail::shared_term(a->weight, b->weight, scoring_);
        ++a;
        ++b;
      }
    }
    return s;
  }

  void insert(Id id, BowVector v) {
    std::uint32_t slot = 0;
    if (!free_.empty()) {
      slot = free_.back();
      free_.pop_back();
    } else {
      detail::check(slots_.size() < std::numeric_limits<std::uint32_t>::max(), "PlaceDatabase::add: the database is full");
      slot = static_cast<std::uint32_t>(slots_.size());
      slots_.emplace_back();
    }
    if (!v.empty() && v.entries.back().word >= postings_.size()) postings_.resize(v.entries.back().word + std::size_t{1});
    for (const auto& e : v.entries) postings_[e.word].push_back({slot, e.weight});
    const double norm = v.empty() ? 1.0 : detail::scoring_norm(v, scoring_);
    slots_[slot] = Slot{id, std::move(v), norm};
    slot_of_.emplace(std::move(id), slot);
  }

  std::size_t words_ = 0;
  BowScoring scoring_ = BowScoring::l1;
  std::vector<std::vector<Posting>> postings_;  ///< per word: (slot, weight)
  std::vector<Slot> slots_;                     ///< images; erased ones are reused
  std::vector<std::uint32_t> free_;             ///< erased slots
  std::map<Id, std::uint32_t> slot_of_;
};

}  // namespace vmap
