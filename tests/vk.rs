//! Vulkan-layer failures surface as typed errors naming the resource, never as panics.
mod common;

use common::*;
use vmls::vk::{Buffer, BufferUsage, Context, ContextOptions, VkError};

#[test]
fn buffer_beyond_the_device_limit_is_refused_by_name() {
    let (ctx, _) = gpu();
    let limit = ctx.info().max_storage_buffer_range;
    match Buffer::new(&ctx, "huge grid", limit + 4, BufferUsage::Storage) {
        Err(e @ VkError::Limit { .. }) => {
            let text = e.to_string();
            assert!(
                text.contains("huge grid") && text.contains("maxStorageBufferRange"),
                "{text}"
            );
        }
        Err(other) => panic!("expected a Limit error, got {other}"),
        Ok(_) => panic!("a buffer beyond maxStorageBufferRange was created"),
    }
    finish(ctx);
}

#[test]
fn out_of_memory_is_an_error_not_a_panic() {
    let (ctx, _) = gpu();
    // 64 TiB of staging memory: no device has it.
    match Buffer::new(&ctx, "absurd staging", 1u64 << 46, BufferUsage::Staging) {
        Err(e) => assert!(e.to_string().contains("absurd staging"), "{e}"),
        Ok(_) => panic!("a 64 TiB buffer was allocated"),
    }
    assert_eq!(ctx.live_allocations(), 0);
    finish(ctx);
}

#[test]
fn unknown_device_names_the_available_ones() {
    let err = Context::new(&ContextOptions {
        validation: Some(false),
        sync_validation: None,
        device: Some("no-such-device".into()),
        force_staging: false,
    })
    .err()
    .expect("no device should match");
    let text = err.to_string();
    assert!(
        text.contains("no-such-device") && text.contains("0: "),
        "{text}"
    );
}
