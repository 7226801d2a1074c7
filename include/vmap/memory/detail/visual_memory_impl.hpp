#pragma once

// The longer members of VisualMemory (memory/visual_memory.hpp), defined apart so that
// the class reads as its wiring: localization, GCS training, merging, the records a
// memory gives and is rebuilt from (memory/records.hpp), the undo of a failed push, and
// the loop search of each new key image. Included by visual_memory.hpp only.

#include <vmap/memory/visual_memory.hpp>

namespace vmap {

template <Descriptor D, Matcher M, Estimator E, Similarity S>
MemoryRecords VisualMemory<D, M, E, S>::records(const RecordsHeld& held, bool complete_score) const {
    const VisualMap& map = selector_.map();
    const std::size_t m = map.keys.size();
    detail::check(held.keys <= m && held.loops <= loops_.size() && held.sessions <= sessions_.size() &&
                      held.bows <= database().size(),
                  "VisualMemory::records: the back-end holds more than the memory");
    MemoryRecords r;
    r.options = options_;
    r.policies = policies_;
    r.frames = map.frames;
    r.first_key = held.keys;
    for (std::size_t k = held.keys; k < m; ++k) {
      KeyImageRecord key{map.keys[k], poses_[k], labels_.key_detections[k]};
      if (!holds_features(k)) key.key.features = key_features(static_cast<std::uint32_t>(k));
      r.keys.push_back(std::move(key));
    }
    for (std::size_t k = std::max<std::size_t>(held.keys, 1); k < m; ++k) r.links.push_back(map.pairs[k - 1]);
    r.first_loop = held.loops;
    r.loops.assign(loops_.begin() + static_cast<std::ptrdiff_t>(held.loops), loops_.end());
    r.first_bow = held.bows;
    for (std::size_t k = held.bows; k < database().size(); ++k)
      r.bows.push_back(*database().bow(static_cast<std::uint32_t>(k)));
    r.words = vocabulary_->size();
    const SelectorState<Features> s = complete_score ? selector_.pending_state() : selector_.deferred_state();
    if (s.previous) {
      const PreparedFrame<Features>& p = *s.previous;
      KeyImage k;
      k.frame_index = p.index;
      k.name = p.name;
      k.timestamp = p.timestamp;
      k.time_ns = p.time_ns;
      k.features = p.item;
      k.image = p.image;
      r.selector.previous = KeyImageRecord{std::move(k), previous_pose_, labels_.previous_detections};
    }
    r.selector.previous_score = s.previous_score;
    r.selector.degeneracy_deferred = s.degeneracy_deferred;
    r.selector.last_frame_index = last_index_;
    const bool learned = !vocabulary_->empty();
    if (!held.vocabulary_written || (learned && !*held.vocabulary_written)) r.vocabulary = vocabulary_;
    r.labelled = labels_.labelled;
    r.schema = labels_.schema;
    r.gcs_written = held.gcs != gcs_generation_;
    if (r.gcs_written) r.gcs = gcs_;
    r.engine = engine_ ? engine_->state() : LoopEngineState{};
    r.first_session = held.sessions;
    r.sessions.assign(sessions_.begin() + static_cast<std::ptrdiff_t>(held.sessions), sessions_.end());
    return r;
  }

template <Descriptor D, Matcher M, Estimator E, Similarity S>
VisualMemory<D, M, E, S> VisualMemory<D, M, E, S>::from_records(MemoryRecords r, const std::string& name, D descriptor,
                                                                  M matcher, E estimator, S similarity, bool pixels_unread) {
    const auto bad = [&](const std::string& what) { detail::fail(ErrorKind::corrupt, name + ": " + what); };
    if (r.first_key != 0 || r.first_loop != 0 || r.first_bow != 0 || r.first_session != 0 || !r.vocabulary || !r.gcs_written)
      bad("the records are not a whole memory");
    std::optional<VisualMemory> built;
    try {
      built.emplace(std::move(descriptor), std::move(matcher), std::move(estimator), std::move(similarity), r.options);
    } catch (const Error& e) {
      bad(e.what());
    }
    VisualMemory& mem = *built;
    mem.pixels_unread_ = pixels_unread;
    mem.labels_.labelled = r.labelled;
    mem.check_policies(r.policies, name);
    const std::size_t m = r.keys.size();
    if (m > r.frames) bad(std::to_string(m) + " key images for " + std::to_string(r.frames) + " frames");
    if (r.links.size() != (m == 0 ? 0 : m - 1)) bad(std::to_string(r.links.size()) + " links for " + std::to_string(m) + " key images");
    mem.sessions_ = r.sessions.empty() ? std::vector<MemorySession>{MemorySession{}} : r.sessions;
    if (mem.sessions_.front().first_key != 0 || mem.sessions_.front().first_frame != 0)
      bad("the first session does not start at key image 0 and frame 0");
    for (std::size_t i = 1; i < mem.sessions_.size(); ++i) {
      // The first frame of a session is a key image, so every session but the last holds
      // one; the last holds none only while no frame was pushed into it.
      const MemorySession& s = mem.sessions_[i];
      const MemorySession& before = mem.sessions_[i - 1];
      if (s.first_key <= before.first_key || s.first_frame <= before.first_frame || s.first_key > m ||
          s.first_frame > r.frames || (s.first_key == m) != (s.first_frame == r.frames))
        bad("session " + std::to_string(i) + " does not start after session " + std::to_string(i - 1) + " (key image " +
            std::to_string(s.first_key) + ", frame " + std::to_string(s.first_frame) + ")");
    }

    SelectorState<Features> state;
    state.map.frames = r.frames;
    for (std::size_t i = 0; i < m; ++i) {
      KeyImageRecord& k = r.keys[i];
      mem.check_layout(k.key.features, name, [&] { return "key image " + std::to_string(i); });
      // Frame indices increase within a session (each run numbers its own frames).
      if (i > 0 && !mem.starts_session(i) && k.key.frame_index <= state.map.keys.back().frame_index)
        bad("key image frame indices are not increasing within a session (key image " + std::to_string(i) + ")");
      if (!mem.labels_.labelled && !k.detections.empty()) bad("detections in a memory without labels");
      mem.poses_.push_back(std::move(k.pose));
      mem.labels_.key_detections.push_back(std::move(k.detections));
      state.map.keys.push_back(std::move(k.key));
    }
    state.map.pairs = std::move(r.links);
    for (LoopEdge& e : r.loops) {
      if (e.from >= m || e.link.key >= e.from) bad("loop edge between invalid key images");
      mem.loops_.push_back(std::move(e));
    }
    if (r.selector.previous) {
      KeyImageRecord& p = *r.selector.previous;
      mem.check_layout(p.key.features, name, [] { return std::string("the previous frame"); });
      if (m == 0 || p.key.frame_index <= state.map.keys.back().frame_index) bad("the previous frame is not after the key image");
      if (!r.labelled && !p.detections.empty()) bad("detections in a memory without labels");
      state.previous = PreparedFrame<Features>{std::move(p.key.features), p.key.frame_index, std::move(p.key.name),
                                               p.key.timestamp, std::move(p.key.image), p.key.time_ns};
      mem.previous_pose_ = std::move(p.pose);
      mem.labels_.previous_detections = std::move(p.detections);
    }
    state.previous_score = std::move(r.selector.previous_score);
    state.degeneracy_deferred = r.selector.degeneracy_deferred;
    mem.last_index_ = r.selector.last_frame_index;
    if (m > 0 && !mem.last_index_) bad("key images but no last frame");
    mem.vocabulary_ = std::move(r.vocabulary);
    mem.labels_.schema = std::move(r.schema);
    const MemoryOptions& o = mem.options_;
    if (mem.labels_.schema && o.labels.order.empty() && (!r.labelled || m < o.labels.sample)) bad("a schema before its sample");
    if (r.labelled && o.labels.order.empty() && !mem.labels_.schema && m >= o.labels.sample) bad("no schema after the sample");
    if (!r.labelled && !o.labels.order.empty() && !mem.labels_.schema) bad("a given label order but no schema");
    mem.gcs_ = std::move(r.gcs);
    if (r.words != mem.vocabulary_->size()) bad("the place database does not match the vocabulary");
    if (r.bows.size() > m) bad(std::to_string(r.bows.size()) + " bags of words for " + std::to_string(m) + " key images");
    if (!r.bows.empty()) {
      if (!mem.detecting()) bad("key images checked for loops without a vocabulary or a label schema");
      std::vector<std::pair<std::uint32_t, BowVector>> images;
      for (std::size_t k = 0; k < r.bows.size(); ++k) images.emplace_back(static_cast<std::uint32_t>(k), std::move(r.bows[k]));
      mem.start_engine(PlaceDatabase<std::uint32_t>::from_records(o.scoring, r.words, std::move(images)));
      std::vector<LabelVector> labels;
      for (std::size_t k = 0; k < mem.engine_->ranker().database().size(); ++k) labels.push_back(mem.label_vector(k));
      try {
        // The session of the last key image checked: as the engine was when it checked it.
        const std::size_t last_checked = mem.engine_->ranker().database().size() - 1;
        mem.engine_->restore(std::move(labels), r.engine, mem.sessions_[mem.session_of_key(last_checked)].first_key);
      } catch (const Error& e) {
        bad(std::string("the loop engine's state: ") + e.what());
      }
    } else if (r.engine.past_window != 0 || r.engine.consistency.last) {
      bad("the loop engine's state without a key image checked for loops");
    }
    for (LoopEdge& e : mem.loops_) e.link.model_kind = mem.model_kind();
    try {
      mem.selector_.restore(std::move(state));
    } catch (const Error& e) {
      bad(e.what());
    }
    if (m > 0 && mem.sessions_.back().first_key == m) mem.selector_.start_chain();  // a session started, no frame yet
    return std::move(*built);
  }

template <Descriptor D, Matcher M, Estimator E, Similarity S>
void VisualMemory<D, M, E, S>::merge(VisualMemory&& other, const std::string& name, const std::string& other_name) {
    const auto refuse = [&](const std::string& why, ErrorKind kind = ErrorKind::invalid_argument) {
      detail::fail(kind, "cannot merge " + other_name + " into " + name + ": " + why);
    };
    if (other.frames() == 0) return;
    if (policies_ != other.policies_)
      refuse("they were made with other policies (" + policies_[0] + " against " + other.policies_[0] + ", ...)",
             ErrorKind::policy_mismatch);
    if (options_record() != other.options_record())
      refuse("they were made with other options (threshold, key images' storage, vocabulary, loop, label or decision "
             "options)",
             ErrorKind::policy_mismatch);
    if (frames() > 0 && labels_.labelled != other.labels_.labelled)
      refuse(std::string("the frames of ") + (labels_.labelled ? name : other_name) +
             " came with detections, the other's without");
    if (other.released_ > 0) refuse(other_name + " holds only its working memory's features in RAM (load it whole)");
    if (pixels_unread_ || other.pixels_unread_) refuse("a memory was loaded without its key images' pixels");
    // Checked: from here on nothing refuses.

    const std::size_t m0 = key_images();
    const std::size_t f0 = frames();
    const std::size_t added = other.key_images();
    const std::size_t other_frames = other.frames();
    SelectorState<Features> state = other.selector_.pending_state();
    state.map = selector_.take_map();
    VisualMap theirs = other.selector_.take_map();
    for (std::size_t i = 0; i < added; ++i) {
      if (i > 0)
        state.map.pairs.push_back(theirs.pairs[i - 1]);
      else if (m0 > 0)
        state.map.pairs.push_back(KeyPair{});  // other's first session starts a chain here
      state.map.keys.push_back(std::move(theirs.keys[i]));
    }
    state.map.frames = f0 + other_frames;
    selector_.restore(std::move(state));
    if (m0 == 0) {
      sessions_.clear();
      labels_.labelled = other.labels_.labelled;
    } else if (sessions_.size() > 1 && sessions_.back().first_frame == f0) {
      sessions_.pop_back();  // a session started here and never pushed into: other's first takes its place
    }
    for (const MemorySession& s : other.sessions_) sessions_.push_back({s.first_key + m0, s.first_frame + f0});
    poses_.insert(poses_.end(), other.poses_.begin(), other.poses_.end());
    const auto& theirs_detections = other.labels_.key_detections;
    labels_.key_detections.insert(labels_.key_detections.end(), theirs_detections.begin(), theirs_detections.end());
    previous_pose_ = other.previous_pose_;
    labels_.previous_detections = other.labels_.previous_detections;
    last_index_ = other.last_index_;
    if (sessions_.back().first_key == key_images()) selector_.start_chain();
    for (std::size_t k = m0; k < key_images(); ++k) {
      std::vector<LoopEdge> found;
      on_new_key(static_cast<std::uint32_t>(k), found);
    }
  }

template <Descriptor D, Matcher M, Estimator E, Similarity S>
MemoryLocalization VisualMemory<D, M, E, S>::localize(const cv::Mat& image, const PlaceDecisionOptions* decision) {
    detail::check(!image.empty(), "VisualMemory::localize: the query image is empty");
    MemoryLocalization out;
    const VisualMap& map = selector_.map();
    if (map.keys.empty()) return out;
    const Features q = selector_.front_end().descriptor().extract(image);
    if (q.empty()) {
      out.reason_code = DecisionReason::no_query_features;
      out.reason = "the query image has no features";
      return out;
    }
    const auto lookup = [this](std::size_t k) -> const Features& { return feature_ref(k); };
    PlaceDecision d;
    if (engine_) {
      d = engine_->localize(q, options_.localize_top_k, lookup, std::nullopt, decision);
    } else {
      // No vocabulary yet: every key image is verified, by an engine without a ranker.
      LoopOptions o = options_.loops;
      o.index = CandidateIndex::brute_force;
      const Engine all(selector_.front_end().matcher(), selector_.front_end().estimator(), o);
      d = all.localize(q, options_.localize_top_k, lookup, map.keys.size(), decision);
    }
    out.status = d.status;
    out.reason_code = d.reason_code;
    out.reason = d.reason;
    out.confidence = d.confidence;
    out.evidence = d.evidence;
    out.verified_candidates = d.verifications;
    out.relative_pose = d.verification.relative_pose;
    // Every verified candidate, the decision's first, then by confidence.
    std::vector<const PlaceCandidate*> verified;
    for (const PlaceCandidate& c : d.considered)
      if (c.stage == CandidateStage::chosen || c.stage == CandidateStage::weaker) verified.push_back(&c);
    std::stable_sort(verified.begin(), verified.end(), [](const PlaceCandidate* a, const PlaceCandidate* b) {
      return (a->stage == CandidateStage::chosen) > (b->stage == CandidateStage::chosen) ||
             ((a->stage == CandidateStage::chosen) == (b->stage == CandidateStage::chosen) && a->confidence > b->confidence);
    });
    for (const PlaceCandidate* c : verified) {
      out.matches.push_back(link_of(*c, q));
      out.match_evidence.push_back(c->evidence);
    }
    if (gcs_) out.position = gcs_->localize(q);
    // The metric pose at the decision's candidate: the answer's when it was accepted, kept
    // aside otherwise for a sequence that accepts the image there (memory/sequence.hpp).
    if (d.best) {
      PoseAnswer a = metric_pose(q, static_cast<std::uint32_t>(*d.best), d.best_matches, d.verification);
      if (out.ok()) {
        out.pose = std::move(a.pose);
        out.pose_reason_code = a.reason_code;
        out.pose_reason = std::move(a.reason);
      } else {
        out.candidate_pose = std::move(a);
      }
    }
    return out;
  }

template <Descriptor D, Matcher M, Estimator E, Similarity S>
PoseAnswer VisualMemory<D, M, E, S>::metric_pose(const Features& query, std::uint32_t key, const Matches& matches,
                                                 const Verification& verification) const {
    const std::size_t m = key_images();
    detail::check(key < m, [&] { return "VisualMemory::metric_pose: key " + std::to_string(key) + " of " + std::to_string(m); });
    const Camera* cam = camera();
    if (!cam)
      return {std::nullopt, PoseReason::no_camera,
              "the memory has no camera: a metric pose needs its calibration (build the memory with --camera FILE)"};
    const auto* key_pose = std::get_if<cv::Affine3d>(&poses_[key]);
    if (!key_pose)
      return {std::nullopt, PoseReason::no_key_pose,
              "key image " + std::to_string(key) + " has no SE(3) pose (build the memory with --poses FILE)"};
    if (!verification.ok()) return {std::nullopt, PoseReason::few_inliers, "the key image was not verified"};
    // The posed key images beside `key` in its session's chain, nearest first.
    const std::size_t session = session_of_key(key);
    const std::size_t first = sessions_[session].first_key;
    const std::size_t end = session + 1 < sessions_.size() ? sessions_[session + 1].first_key : m;
    std::vector<std::uint32_t> partners;
    for (std::size_t d = 1; d <= pose_options_.chain_reach; ++d) {
      if (key >= first + d && std::holds_alternative<cv::Affine3d>(poses_[key - d])) partners.push_back(key - static_cast<std::uint32_t>(d));
      if (key + d < end && std::holds_alternative<cv::Affine3d>(poses_[key + d])) partners.push_back(key + static_cast<std::uint32_t>(d));
    }
    // Released key images' features are read (copies, held here); the others are referenced.
    std::vector<Features> read;
    read.reserve(partners.size() + 1);
    const auto features_of = [&](std::uint32_t k) -> const Features* {
      if (holds_features(k)) return &selector_.map().keys[k].features;
      read.push_back(key_features(k));
      return &read.back();
    };
    const Features* key_f = features_of(key);
    std::vector<PosedView> views;
    for (std::uint32_t p : partners) views.push_back({features_of(p), std::get<cv::Affine3d>(poses_[p])});
    return place_query(query, matches, verification, key, *key_f, *key_pose, views, selector_.front_end().matcher(), *cam,
                       pose_options_);
  }

template <Descriptor D, Matcher M, Estimator E, Similarity S>
PoseAnswer VisualMemory<D, M, E, S>::loop_pose(const LoopEdge& edge) const {
    const std::size_t m = key_images();
    detail::check(edge.from < m && edge.link.key < m, "VisualMemory::loop_pose: the edge's key images are not in the memory");
    const Features from = key_features(edge.from);
    const Features to = key_features(edge.link.key);
    const Matches matches = selector_.front_end().matcher().match(from, to);
    const Verification v = selector_.front_end().estimator().verify(from, to, matches);
    return metric_pose(from, edge.link.key, matches, v);
  }

template <Descriptor D, Matcher M, Estimator E, Similarity S>
GcsTrainStats VisualMemory<D, M, E, S>::train_gcs(const MemoryGcsOptions& options) {
    const VisualMap& map = selector_.map();
    std::vector<std::uint32_t> keys;
    std::vector<Features> features;
    std::vector<Pose2> poses;
    for (std::size_t k = 0; k < map.keys.size(); ++k)
      if (const auto* p = std::get_if<Pose2>(&poses_[k])) {
        keys.push_back(static_cast<std::uint32_t>(k));
        features.push_back(key_features(static_cast<std::uint32_t>(k)));
        poses.push_back(*p);
      }
    detail::check(keys.size() >= 3, "VisualMemory::train_gcs: " + std::to_string(keys.size()) +
                                        " key images have an SE(2) pose, the GCS needs at least 3");
    for (const Features& f : features)
      detail::check(f.descriptors.empty() || f.descriptors.type() == CV_8UC1,
                    "VisualMemory::train_gcs: the BowHistogram needs binary (CV_8UC1) descriptors, the key images "
                    "have " + cv::typeToString(f.descriptors.type()));
    BowHistogram histogram(options.histogram);
    PoseMapTraining<GcsXf> trained = train_pose_map<GcsXf>(histogram, options.gcs, features, poses);
    gcs_.emplace(MemoryGcs{options, std::move(histogram), std::move(trained.map), std::move(keys),
                           std::move(trained.winners)});
    ++gcs_generation_;
    return trained.gcs;
  }

template <Descriptor D, Matcher M, Estimator E, Similarity S>
void VisualMemory<D, M, E, S>::rollback(PushCheckpoint c) {
    selector_.rollback(std::move(c.selector));
    poses_.resize(c.keys);
    labels_.key_detections.resize(c.keys);
    loops_.resize(c.loops);
    heavy_.clear();  // rebuilt from the place database when next needed
    previous_pose_ = std::move(c.previous_pose);
    labels_.previous_detections = std::move(c.previous_detections);
    last_index_ = c.last_index;
    labels_.labelled = c.labelled;
    labels_.schema = std::move(c.schema);
    vocabulary_ = std::move(c.vocabulary);
    read_.reset();
    if (!c.engine_frames) {
      engine_.reset();
      return;
    }
    // The engine as it was: its database without the key images this push added, its
    // label vectors and state, the tree rebuilt from them (LoopEngine::restore).
    PlaceDatabase<std::uint32_t> db = engine_->ranker().database();
    for (std::size_t k = *c.engine_frames; k < engine_->frames(); ++k) (void)db.erase(static_cast<std::uint32_t>(k));
    std::vector<LabelVector> labels(engine_->labels().begin(),
                                    engine_->labels().begin() + static_cast<std::ptrdiff_t>(*c.engine_frames));
    start_engine(std::move(db));
    engine_->restore(std::move(labels), c.engine_state, c.engine_session);
  }

template <Descriptor D, Matcher M, Estimator E, Similarity S>
void VisualMemory<D, M, E, S>::on_new_key(std::uint32_t key, std::vector<LoopEdge>& found) {
    const auto& keys = selector_.map().keys;
    // Key images 0 .. key count (merge() appends later ones before it checks these).
    const std::size_t known = std::size_t{key} + 1;
    sample_schema(known);
    if (vocabulary_->empty()) {
      if (known < options_.vocabulary_after) return;
      std::vector<cv::Mat> sets;
      for (std::size_t k = 0; k < known; ++k)
        sets.push_back(holds_features(k) ? keys[k].features.descriptors : key_features(static_cast<std::uint32_t>(k)).descriptors);
      std::size_t rows = 0;
      for (const auto& d : sets) rows += static_cast<std::size_t>(d.rows);
      // Too few descriptors to split into `branching` words (blank frames): try again
      // at the next key image.
      if (rows < static_cast<std::size_t>(std::max(options_.vocabulary.branching, 1))) return;
      vocabulary_ = std::make_shared<const AnyVocabulary>(AnyVocabulary::learn(sets, options_.vocabulary));
    }
    if (!detecting()) return;
    if (!engine_) start_engine(PlaceDatabase<std::uint32_t>(vocabulary_->size(), options_.scoring));
    // The engine holds exactly the key images already checked, in order.
    const auto lookup = [this](std::size_t k) -> const Features& { return feature_ref(k); };
    for (std::size_t k = engine_->frames(); k <= key; ++k) {
      // A query the working memory no longer holds (a catch-up after the label sample)
      // is read once and kept here: the lookup's own copy is replaced at its next read.
      if (k > 0 && starts_session(k)) engine_->begin_session();
      std::optional<Features> read;
      const Features& query = holds_features(k) ? keys[k].features : read.emplace(key_features(static_cast<std::uint32_t>(k)));
      const PlaceDecision d = engine_->add(query, label_vector(k), lookup);
      if (d.accepted())
        for (const PlaceCandidate& c : d.considered)
          if (c.stage == CandidateStage::chosen) {
            loops_.push_back({static_cast<std::uint32_t>(k), link_of(c, query)});
            found.push_back(loops_.back());
          }
      if (session_of_key(k) > 0) link_sessions(static_cast<std::uint32_t>(k), query, found);
    }
  }

template <Descriptor D, Matcher M, Estimator E, Similarity S>
void VisualMemory<D, M, E, S>::link_sessions(std::uint32_t k, const Features& query, std::vector<LoopEdge>& found) {
    const BowVector* bow = database().bow(k);
    if (!bow) return;
    const auto first = static_cast<std::uint32_t>(sessions_[session_of_key(k)].first_key);
    // The heavy words of every key image of the earlier sessions, indexed in order as
    // sessions need them (a key image the place database lacks has none).
    while (heavy_.next() < first) {
      const std::uint32_t id = heavy_.next();
      const BowVector* b = database().bow(id);
      heavy_.add(id, b ? heavy_words(*b) : std::vector<HeavyWord>{});
    }
    std::vector<HeavyIndex::Hit> hits = heavy_.query(heavy_words(*bow), first, heavy_units(run_link_min_score));
    if (hits.size() > run_link_candidates) hits.resize(run_link_candidates);
    for (const HeavyIndex::Hit& h : hits) {
      std::optional<PlaceLink> link = link_pair(query, feature_ref(h.id), heavy_score(h.units));
      if (!link) continue;
      link->key = h.id;
      loops_.push_back({k, *link});
      found.push_back(loops_.back());
    }
  }

template <Descriptor D, Matcher M, Estimator E, Similarity S>
std::optional<PlaceLink> VisualMemory<D, M, E, S>::link_pair(const Features& query, const Features& candidate,
                                                             double score) {
    if (!engine_) return std::nullopt;
    const bool flip = detail::features_before(candidate, query);
    const Features& a = flip ? candidate : query;
    const Features& b = flip ? query : candidate;
    const auto lookup = [&b](std::size_t) -> const Features& { return b; };
    PlaceDecisionOptions decision = options_.loops.decision;
    decision.min_confidence = std::max(decision.min_confidence, run_link_min_confidence);
    const PlaceDecision d = engine_->decide(a, {{0, score}}, lookup, &decision);
    if (!d.accepted()) return std::nullopt;
    for (const PlaceCandidate& c : d.considered)
      if (c.stage == CandidateStage::chosen) {
        PlaceLink l = link_to(c, a, b);
        // Verified as (candidate, query): x_candidate^T F x_query = 0, so the link from the
        // query holds F^T (E^T alike).
        if (flip) l.model = l.model.t();
        return l;
      }
    return std::nullopt;
  }

template <Descriptor D, Matcher M, Estimator E, Similarity S>
MemoryStep VisualMemory<D, M, E, S>::push_frame(const Frame& frame, const OdometryPose& pose,
                                                const std::vector<Detection>* detections) {
    const bool with = detections != nullptr;
    if (last_index_ && with != labels_.labelled)
      detail::fail("VisualMemory::push: frame " + std::to_string(frame.index) +
                   (with ? " comes with detections, but the memory's frames had none"
                         : " comes without detections, but the memory's frames had them (give an empty list when "
                           "nothing was detected)"));
    // Values are checked before anything changes, so a bad one leaves the memory as it was.
    detail::check_pushed_frame({frame.image, frame.index, frame.name, frame.timestamp}, pose, sessions_.back().first_frame == frames() ? std::nullopt : last_index_);
    if (with) (void)present_labels(*detections, options_.loops.labels.min_score);
    PushCheckpoint mark = checkpoint();
    try {
      if (!last_index_) labels_.labelled = with;  // the first frame decides
      MemoryStep step;
      step.frame = selector_.push(frame);
      after_push(step, frame.index, pose, detections);
      return step;
    } catch (...) {
      rollback(std::move(mark));
      throw;
    }
  }

template <Descriptor D, Matcher M, Estimator E, Similarity S>
PlaceLink VisualMemory<D, M, E, S>::link_of(const PlaceCandidate& c, const Features& query) {
    return link_to(c, query, feature_ref(c.frame));
  }

template <Descriptor D, Matcher M, Estimator E, Similarity S>
PlaceLink VisualMemory<D, M, E, S>::link_to(const PlaceCandidate& c, const Features& query, const Features& candidate) {
    PlaceLink l;
    l.key = static_cast<std::uint32_t>(c.frame);
    l.bow_score = std::clamp(c.bow_score, 0.0, 1.0);
    l.status = c.status;
    l.model = c.model;
    l.model_kind = model_kind();
    l.matches = c.matches;
    l.inliers = c.inliers;
    l.confidence = c.confidence;
    Verification v;
    v.status = c.status;
    v.model = c.model;
    v.inliers = c.inliers;
    v.matches = c.matches;
    l.similarity = selector_.front_end().similarity()(query, candidate, v);
    return l;
  }

template <Descriptor D, Matcher M, Estimator E, Similarity S>
void VisualMemory<D, M, E, S>::after_push(MemoryStep& step, std::size_t index, const OdometryPose& pose,
                                          const std::vector<Detection>* detections) {
    const FrameResult& r = step.frame;
    static const std::vector<Detection> none;
    const std::vector<Detection>& current = detections ? *detections : none;
    if (r.key_taken) {
      // Eq. 6 takes I_{j-1}: its pose and detections are the ones pushed with it.
      const bool this_frame = *r.key_frame == index;
      poses_.push_back(this_frame ? pose : previous_pose_);
      labels_.key_detections.push_back(this_frame ? current : labels_.previous_detections);
      step.new_key = static_cast<std::uint32_t>(key_images() - 1);
      on_new_key(*step.new_key, step.loops);
    }
    previous_pose_ = pose;
    labels_.previous_detections = current;
    last_index_ = index;
  }

template <Descriptor D, Matcher M, Estimator E, Similarity S>
void VisualMemory<D, M, E, S>::check_policies(const std::array<std::string, 4>& recorded, const std::string& name) const {
    static constexpr const char* roles[4] = {"descriptor", "matcher", "estimator", "similarity"};
    for (std::size_t i = 0; i < 4; ++i)
      if (!recorded[i].empty() && recorded[i] != policies_[i])
        detail::fail(ErrorKind::policy_mismatch, name + ": the " + roles[i] + " given to load (" +
                     (policies_[i].empty() ? std::string("not recorded") : policies_[i]) +
                     ") is not the one the memory was built with (" + recorded[i] + ")");
  }

template <Descriptor D, Matcher M, Estimator E, Similarity S>
Features VisualMemory<D, M, E, S>::key_features(std::uint32_t k) const {
    const std::size_t m = key_images();
    detail::check(k < m, [&] { return "VisualMemory::key_features: key " + std::to_string(k) + " of " + std::to_string(m); });
    if (holds_features(k)) return selector_.map().keys[k].features;
    Features f = source_(k);
    const Features& kept = selector_.map().keys[k].features;  // released: its norm and image size remain
    detail::check(f.norm == kept.norm && f.image_size == kept.image_size, [&] {
      return "VisualMemory: the features read for key image " + std::to_string(k) +
             " are not that key image's (another norm or image size)";
    });
    return f;
  }

}  // namespace vmap
