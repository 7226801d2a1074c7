// Compiles the test targets' precompiled header once; the tests reuse it.
