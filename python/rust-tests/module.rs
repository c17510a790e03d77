//! The native module's Rust side as a library: its sensor-block layout is the struct's. Being
//! an integration test, this also makes `cargo test --workspace` build the library itself, and
//! with it the `lib_iwsim.so` extension module that `tests/e2e/python.rs` hands to pytest.

#[test]
fn the_reported_layout_ends_within_the_struct() {
    let layout = _iwsim::layout_for_tests();
    let (name, offset, _, _) = layout.last().copied().expect("fields");
    assert_eq!(name, "visited_mask");
    assert!(offset + 8 <= core::mem::size_of::<ipc_types::SensorBlock>());
}
