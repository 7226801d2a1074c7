"""vmap.Vocabulary, bags of words and vmap.PlaceDatabase (examples/python/part_place.cpp).

The values are checked against the library's other faces: the `vmap vocabulary` command
line (a vocabulary it learns or converts is byte-identical to the module's), and the bags
of words ORB-SLAM2, DBoW2 and FBoW computed with their own code (../shared/data/vocabularies,
as tests/unit/place/test_vocabulary_formats.cpp checks them in C++).
"""

import pathlib
import pickle
import subprocess

import numpy
import pytest

import vmap

SEED = 3


@pytest.fixture(scope="module")
def features(sample_frames):
    orb = vmap.Descriptor("orb")
    return [orb.extract(image) for image, _, _ in sample_frames]


@pytest.fixture(scope="module")
def vocabulary(features):
    return vmap.Vocabulary.learn(features, seed=SEED)


@pytest.fixture(scope="module")
def float_descriptors():
    rng = numpy.random.default_rng(7)
    return [rng.random((80, 16), dtype=numpy.float32) for _ in range(6)]


def vocabularies_dir(shared):
    return shared / "data" / "vocabularies"


def read_descriptors(path):
    """test_orb1000_descriptors.txt: "image row hex" lines, as one uint8 N x 32 array per image."""
    rows = {}
    for line in pathlib.Path(path).read_text().splitlines():
        image, row, hexa = line.split()
        rows.setdefault(image, []).append((int(row), bytes.fromhex(hexa)))
    out = {}
    for image, items in rows.items():
        items.sort()
        assert [r for r, _ in items] == list(range(len(items)))
        out[image] = numpy.frombuffer(b"".join(b for _, b in items), dtype=numpy.uint8).reshape(-1, 32)
    return out


def read_bows(path):
    """"image word weight" lines, as {image: {word: weight}} in file order."""
    out = {}
    for line in pathlib.Path(path).read_text().splitlines():
        image, word, weight = line.split()
        out.setdefault(image, {})[int(word)] = float(weight)
    return out


# --- learning ------------------------------------------------------------------------


def test_learning_is_deterministic_for_a_seed(features, vocabulary):
    again = vmap.Vocabulary.learn(features, seed=SEED)
    assert again.to_bytes() == vocabulary.to_bytes()
    assert numpy.array_equal(again.word_centres, vocabulary.word_centres)
    assert numpy.array_equal(again.idf, vocabulary.idf)
    other = vmap.Vocabulary.learn(features, seed=SEED + 1)
    assert other.to_bytes() != vocabulary.to_bytes()


def test_properties(vocabulary):
    v = vocabulary
    assert v.branching == 10 and v.depth == 3
    assert 100 < v.words <= 1000 and len(v) == v.words
    assert v.binary and v.norm == "hamming"
    assert v.descriptor_dtype == numpy.uint8 and v.descriptor_size == 32
    assert v.weighting == "tf_idf_l1" and v.scoring == "l1"
    assert v.idf.dtype == numpy.float32 and v.idf.shape == (v.words,)
    assert numpy.all(v.idf >= 0)
    assert v.word_centres.dtype == numpy.uint8 and v.word_centres.shape == (v.words, 32)
    assert v.nodes > v.words
    assert v.memory_bytes > v.words * 32
    assert repr(v).startswith(f"<vmap.Vocabulary {v.words} words (branching 10, depth 3), binary x 32")


def test_learning_from_arrays_equals_learning_from_features(features, vocabulary):
    arrays = [f.descriptors for f in features]
    assert vmap.Vocabulary.learn(arrays, seed=SEED).to_bytes() == vocabulary.to_bytes()


def test_options_are_used(features):
    v = vmap.Vocabulary.learn(features, branching=4, depth=2, iterations=3, max_descriptors=5000, seed=SEED)
    assert v.branching == 4 and v.depth == 2 and v.words <= 16


def test_float_vocabulary_round_trips(float_descriptors, tmp_path):
    v = vmap.Vocabulary.learn(float_descriptors, branching=4, depth=2, seed=1)
    assert not v.binary and v.norm == "l2"
    assert v.descriptor_dtype == numpy.float32 and v.descriptor_size == 16
    assert v.word_centres.dtype == numpy.float32
    v.save(tmp_path / "float.voc")
    back = vmap.Vocabulary.load(tmp_path / "float.voc")
    assert back.to_bytes() == v.to_bytes()
    for d in float_descriptors:
        assert back.transform(d) == v.transform(d)
    assert pickle.loads(pickle.dumps(v)).to_bytes() == v.to_bytes()
    with pytest.raises(vmap.Error, match="is a float vocabulary; ORB-SLAM2 text files hold binary ones"):
        v.save(tmp_path / "float.txt")


# --- transform -----------------------------------------------------------------------


def test_dict_and_sparse_forms_agree(features, vocabulary):
    for f in features[:10]:
        bow = vocabulary.transform(f)
        words, weights = vocabulary.transform_sparse(f)
        assert words.dtype == numpy.uint32 and weights.dtype == numpy.float64
        assert list(bow) == words.tolist()
        assert list(bow.values()) == weights.tolist()
        assert numpy.all(numpy.diff(words.astype(numpy.int64)) > 0)
        assert numpy.all(weights > 0)
        assert abs(weights.sum() - 1.0) < 1e-6
        # weights are the library's floats, widened exactly
        assert numpy.array_equal(weights.astype(numpy.float32).astype(numpy.float64), weights)


def test_transform_is_tf_idf_of_the_assigned_words(features, vocabulary):
    f = features[3]
    words = vocabulary.assign(f)
    assert words.dtype == numpy.uint32 and words.shape == (len(f),)
    assert words.max() < vocabulary.words
    counts = numpy.bincount(words, minlength=vocabulary.words)
    tfidf = counts * vocabulary.idf.astype(numpy.float64)
    expected = tfidf / tfidf.sum()
    bow = vocabulary.transform(f)
    assert list(bow) == [w for w in numpy.flatnonzero(expected)]
    for w, x in bow.items():
        assert x == pytest.approx(expected[w], rel=1e-6)


def test_transform_inputs_agree(features, vocabulary):
    f = features[0]
    d = f.descriptors
    want = vocabulary.transform(f)
    assert vocabulary.transform(d) == want
    assert vocabulary.transform(numpy.asfortranarray(d)) == want  # copied once, same values
    padded = numpy.zeros((d.shape[0], 48), dtype=numpy.uint8)
    padded[:, :32] = d
    assert vocabulary.transform(padded[:, :32]) == want  # row-strided view read in place
    many = vocabulary.transform_many(features[:5])
    assert many == [vocabulary.transform(x) for x in features[:5]]
    sparse = vocabulary.transform_many(features[:5], sparse=True)
    for (w, x), bow in zip(sparse, many):
        assert w.tolist() == list(bow) and x.tolist() == list(bow.values())
    assert vocabulary.transform(numpy.zeros((0, 32), dtype=numpy.uint8)) == {}


def test_scores(features, vocabulary):
    a = vocabulary.transform(features[0])
    b = vocabulary.transform(features[1])
    assert vmap.bow_score(a, a) == pytest.approx(1.0, abs=1e-6)
    assert vocabulary.score(a, b) == vmap.bow_score(a, b, "l1")
    assert 0.0 < vmap.bow_score(a, b) < 1.0
    assert vmap.bow_score(a, vocabulary.transform_sparse(features[1])) == vmap.bow_score(a, b)
    assert vmap.bow_score({1: 1.0}, {2: 1.0}, "cosine") == 0.0
    assert vmap.bow_score({1: 1.0, 2: 1.0}, {1: 2.0, 2: 2.0}, "l2") == pytest.approx(1.0)


# --- save, load, convert -------------------------------------------------------------


def test_save_load_round_trips(features, vocabulary, tmp_path):
    vocabulary.save(tmp_path / "v.voc")
    assert (tmp_path / "v.voc").read_bytes() == vocabulary.to_bytes()
    back = vmap.Vocabulary.load(str(tmp_path / "v.voc"))
    assert vmap.Vocabulary.from_bytes(vocabulary.to_bytes()).to_bytes() == vocabulary.to_bytes()
    assert pickle.loads(pickle.dumps(vocabulary)).to_bytes() == vocabulary.to_bytes()
    for f in features[::7]:
        assert back.transform(f) == vocabulary.transform(f)
    # The other formats keep the tree and the word ids: the same word for every descriptor.
    vocabulary.save(tmp_path / "v.txt")
    vocabulary.save(tmp_path / "v.fbow")
    text = vmap.Vocabulary.load(tmp_path / "v.txt")
    fbow = vmap.Vocabulary.load(tmp_path / "v.fbow")
    assert (tmp_path / "v.txt").read_bytes() == vocabulary.to_bytes("orbslam_text")
    assert (tmp_path / "v.fbow").read_bytes() == vocabulary.to_bytes("fbow")
    assert text.weighting == "tf_idf_l1" and fbow.weighting == "fbow" and fbow.scoring == "l2"
    for f in features[::7]:
        want = vocabulary.assign(f)
        assert numpy.array_equal(text.assign(f), want)
        assert numpy.array_equal(fbow.assign(f), want)
        bow, bow_text = vocabulary.transform(f), text.transform(f)
        assert list(bow_text) == list(bow)  # idf written with 6 digits: weights close, words equal
        assert numpy.allclose(list(bow_text.values()), list(bow.values()), rtol=1e-5)
    # an explicit format wins over the name
    vocabulary.save(tmp_path / "other.bin", format="orbslam_text")
    assert (tmp_path / "other.bin").read_bytes() == (tmp_path / "v.txt").read_bytes()


def test_learning_equals_the_command_line(features, vocabulary, vmap_cli, sample_list, tmp_path):
    out = tmp_path / "cli.voc"
    subprocess.run([vmap_cli, "vocabulary", sample_list, "--words", "1000", "--depth", "3", "--seed", str(SEED),
                    "--out", str(out)], check=True, capture_output=True)
    assert out.read_bytes() == vocabulary.to_bytes()
    cli = vmap.Vocabulary.load(out)
    for f in features:
        assert cli.transform(f) == vocabulary.transform(f)


@pytest.mark.parametrize("name", ["orbslam2_k10L3.txt", "dbow2_k10L3.yml.gz", "fbow_k10L3.fbow"])
@pytest.mark.parametrize("ext", [".voc", ".txt", ".fbow"])
def test_converting_equals_the_command_line(shared, vmap_cli, tmp_path, name, ext):
    source = vocabularies_dir(shared) / name
    cli_out = tmp_path / ("cli" + ext)
    run = subprocess.run([vmap_cli, "vocabulary", "convert", str(source), str(cli_out)], capture_output=True, text=True)
    py_out = tmp_path / ("py" + ext)
    v = vmap.Vocabulary.load(source)
    if run.returncode != 0:
        # FBoW's weighting has no DBoW2 scoring: both refuse it with the library's message
        message = run.stderr.strip().split("error: ", 1)[1]
        assert message.startswith("orbslam_text:")
        with pytest.raises(vmap.Error) as e:
            v.save(py_out)
        assert str(e.value) == message
        assert not py_out.exists()
        return
    v.save(py_out)
    assert py_out.read_bytes() == cli_out.read_bytes()


# --- the peer libraries' vocabularies ------------------------------------------------

REFERENCES = [
    # ORB-SLAM2's reference used the 6-digit weights of its text file (as vmap reads
    # them); DBoW2's full-precision ones, held by vmap as float; FBoW's are floats.
    ("orbslam2_k10L3.txt", "orbslam2_bow_reference.txt", "tf_idf_l1", "l1", 1e-6),
    ("dbow2_k10L3.yml.gz", "dbow2_bow_reference.txt", "tf_idf_l1", "l1", 1e-6),
    ("fbow_k10L3.fbow", "fbow_bow_reference.txt", "fbow", "l2", 0.0),
]


@pytest.mark.parametrize("name,reference,weighting,scoring,tolerance", REFERENCES)
def test_peer_vocabularies_give_their_libraries_bags_of_words(shared, tmp_path, name, reference, weighting, scoring,
                                                            tolerance):
    folder = vocabularies_dir(shared)
    images = read_descriptors(folder / "test_orb1000_descriptors.txt")
    assert sorted(images) == ["1.jpg", "20.jpg", "45.jpg", "60.jpg", "84.jpg"]
    want = read_bows(folder / reference)
    v = vmap.Vocabulary.load(folder / name)
    assert v.words == 1000  # no phantom word from the text file's final newline
    assert v.branching == 10 and v.depth == 3 and v.nodes == 1111
    assert v.weighting == weighting and v.scoring == scoring
    assert v.binary and v.descriptor_size == 32
    v.save(tmp_path / "converted.voc")
    back = vmap.Vocabulary.load(tmp_path / "converted.voc")
    for image, d in images.items():
        got = v.transform(d)
        assert list(got) == list(want[image]), image  # word ids exact
        if tolerance == 0.0:
            # %.9g recovers FBoW's float exactly: bit for bit
            assert all(numpy.float32(want[image][w]) == numpy.float32(got[w]) for w in got), image
        else:
            assert max(abs(got[w] - want[image][w]) for w in got) <= tolerance, image
        assert back.transform(d) == got
        w, x = v.transform_sparse(d)
        assert w.tolist() == list(got) and x.tolist() == list(got.values())


def test_text_and_yaml_hold_the_same_tree(shared):
    folder = vocabularies_dir(shared)
    text = vmap.Vocabulary.load(folder / "orbslam2_k10L3.txt")
    yml = vmap.Vocabulary.load(folder / "dbow2_k10L3.yml.gz")
    assert numpy.array_equal(text.word_centres, yml.word_centres)


def test_from_bytes_reads_the_formats_in_memory(shared):
    folder = vocabularies_dir(shared)
    for name in ("orbslam2_k10L3.txt", "fbow_k10L3.fbow"):
        from_file = vmap.Vocabulary.load(folder / name)
        from_bytes = vmap.Vocabulary.from_bytes((folder / name).read_bytes())
        assert from_bytes.to_bytes() == from_file.to_bytes()
    with pytest.raises(vmap.Error, match="read from their file"):
        vmap.Vocabulary.from_bytes((folder / "dbow2_k10L3.yml.gz").read_bytes())


# --- the place database --------------------------------------------------------------


@pytest.fixture()
def database(features, vocabulary):
    db = vmap.PlaceDatabase(vocabulary)
    for f in features:
        db.add(f)
    return db


def test_database_returns_each_frame_for_itself(features, vocabulary, database):
    assert len(database) == database.size == len(features)
    assert database.ids == list(range(len(features)))
    assert database.words == vocabulary.words and database.scoring == "l1"
    assert database.vocabulary is vocabulary
    for i, f in enumerate(features):
        results = database.query(f, 3)
        assert len(results) == 3
        assert results[0].id == i
        assert results[0].score == pytest.approx(1.0, abs=1e-6)
        assert results[0].score >= results[1].score >= results[2].score
        best_id, best_score = results[0]
        assert (best_id, best_score) == (results[0].id, results[0].score)


def test_database_scores_are_bow_scores(features, vocabulary, database):
    q = vocabulary.transform(features[10])
    results = database.query(q, 5)
    assert results == database.query(features[10], 5)
    assert results == database.query(vocabulary.transform_sparse(features[10]), 5)
    for r in results:
        # the database keeps the bags renormalised in float: equal to float rounding
        assert r.score == pytest.approx(vmap.bow_score(q, vocabulary.transform(features[r.id])), abs=1e-7)
    # the stored bag is the transform, L1-normalised again
    stored = database.bow(10)
    assert list(stored) == list(q)
    assert sum(stored.values()) == pytest.approx(1.0, abs=1e-6)
    assert database.bow(12345) is None


def test_database_filters_and_erase(features, database):
    q = features[30]
    assert [r.id for r in database.query(q, 5, only=[3, 30, 40])][0] == 30
    assert {r.id for r in database.query(q, 5, only=[3, 40, 999])} <= {3, 40}
    assert all(r.id < 20 for r in database.query(q, 5, before=20))
    assert database.query(q, 0) == []
    assert 30 in database
    assert database.erase(30) and not database.erase(30)
    assert 30 not in database
    assert all(r.id != 30 for r in database.query(q, 5))
    assert database.add(q) == len(features)  # above every id so far, not the erased one
    assert database.add(q, id=30) == 30
    with pytest.raises(vmap.Error, match="already in the database"):
        database.add(q, id=30)
    database.clear()
    assert len(database) == 0 and database.query(q) == []


def test_database_round_trips(features, vocabulary, database, tmp_path):
    database.save(tmp_path / "places.db")
    assert (tmp_path / "places.db").read_bytes() == database.to_bytes()
    loaded = vmap.PlaceDatabase.load(tmp_path / "places.db", vocabulary=vocabulary)
    pickled = pickle.loads(pickle.dumps(database))
    bare = vmap.PlaceDatabase.from_bytes(database.to_bytes())
    assert bare.vocabulary is None and bare.words == vocabulary.words
    for f in features[::5]:
        want = database.query(f, 5)
        assert loaded.query(f, 5) == want
        assert pickled.query(f, 5) == want
        assert bare.query(vocabulary.transform(f), 5) == want
    assert loaded.add(features[0]) == len(features)
    with pytest.raises(vmap.Error, match="no vocabulary"):
        bare.query(features[0])
    small = vmap.Vocabulary.learn(features, branching=4, depth=2, seed=SEED)
    with pytest.raises(vmap.Error, match="vocabulary of"):
        vmap.PlaceDatabase.load(tmp_path / "places.db", vocabulary=small)


def test_database_without_vocabulary():
    db = vmap.PlaceDatabase(words=10, scoring="cosine")
    assert db.add({1: 1.0, 2: 1.0}) == 0
    assert db.add((numpy.array([3, 2], dtype=numpy.int64), numpy.array([1.0, 1.0]))) == 1
    results = db.query({2: 1.0, 1: 1.0})
    assert [r.id for r in results] == [0, 1]
    assert results[0].score == pytest.approx(1.0)
    assert results[1].score == pytest.approx(0.5)
    with pytest.raises(vmap.Error, match="outside the vocabulary of 10 words"):
        db.add({10: 1.0})
    with pytest.raises(vmap.Error, match="scoring must be"):
        vmap.PlaceDatabase(scoring="dot")


# --- errors --------------------------------------------------------------------------


def test_errors_carry_the_library_message(features, vocabulary, tmp_path):
    with pytest.raises(vmap.Error, match="missing.voc': does not exist"):
        vmap.Vocabulary.load(tmp_path / "missing.voc")
    bad = tmp_path / "bad.voc"
    bad.write_bytes(b"VMAPVOCB" + b"\x00" * 40)
    with pytest.raises(vmap.Error, match="bad.voc"):
        vmap.Vocabulary.load(bad)
    with pytest.raises(vmap.Error, match="no image has descriptors"):
        vmap.Vocabulary.learn([])
    with pytest.raises(vmap.Error, match="no image has descriptors"):
        vmap.Vocabulary.learn([numpy.zeros((0, 32), dtype=numpy.uint8)])
    with pytest.raises(vmap.Error, match="branching must be in 2..4096"):
        vmap.Vocabulary.learn(features, branching=1)
    with pytest.raises(vmap.Error, match="cannot make 10 clusters"):
        vmap.Vocabulary.learn([numpy.zeros((5, 32), dtype=numpy.uint8)])
    with pytest.raises(vmap.Error, match="PlaceDatabase::add: the id is already"):
        db = vmap.PlaceDatabase(vocabulary)
        db.add(features[0], id=4)
        db.add(features[1], id=4)


def test_bad_descriptor_arrays_name_the_argument(features, vocabulary):
    d = features[0].descriptors
    with pytest.raises(vmap.Error, match=r"^descriptors: a float64 array; descriptors are uint8"):
        vocabulary.transform(d.astype(numpy.float64))
    with pytest.raises(vmap.Error, match=r"^descriptors: an array of shape \(32,\)"):
        vocabulary.transform(d[0])
    with pytest.raises(vmap.Error, match=r"^descriptors: a list"):
        vocabulary.transform(d.tolist())
    with pytest.raises(vmap.Error, match=r"^descriptors\[1\]: a int32 array"):
        vmap.Vocabulary.learn([d, d.astype(numpy.int32)])
    with pytest.raises(vmap.Error, match=r"^descriptors: a ndarray; expected a list"):
        vmap.Vocabulary.learn(d)
    with pytest.raises(vmap.Error, match=r"^descriptor_sets: a Features; expected a list"):
        vocabulary.transform_many(features[0])
    with pytest.raises(vmap.Error, match=r"^descriptor_sets\[0\]: a float64 array"):
        vocabulary.transform_many([d.astype(numpy.float64)])
    with pytest.raises(vmap.Error, match="descriptors must be CV_8UC1 with 32 columns"):
        vocabulary.transform(d[:, :16])
    with pytest.raises(vmap.Error, match="descriptors must be CV_8UC1 with 32 columns .* got CV_32FC1"):
        vocabulary.transform(d.astype(numpy.float32))


def test_bad_bags_of_words(vocabulary):
    db = vmap.PlaceDatabase(vocabulary)
    with pytest.raises(vmap.Error, match="word 1 is given twice"):
        db.add((numpy.array([1, 1]), numpy.array([0.5, 0.5])))
    with pytest.raises(vmap.Error, match="word id -1 is not in"):
        db.add({-1: 1.0})
    with pytest.raises(vmap.Error, match="a key of type str"):
        db.query({"1": 1.0})
    with pytest.raises(vmap.Error, match="weight of word 3 is negative"):
        db.add({3: -1.0})
    with pytest.raises(vmap.Error, match="word ids are a float64 array"):
        db.add((numpy.array([1.0]), numpy.array([1.0])))
    with pytest.raises(vmap.Error, match="1-D and of one length"):
        db.add((numpy.array([1, 2]), numpy.array([1.0])))
    with pytest.raises(vmap.Error, match="a bag of words is"):
        vmap.bow_score([1, 2], {1: 1.0})
