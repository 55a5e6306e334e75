//! One way to build a field out of other fields: an [`Adapter`] names the field it
//! rests on ([`Adapter::base`]) and overrides only what it changes; [`Adapted`] turns
//! it into a [`FieldSource`], every method it leaves alone delegated to the base.
//! It lives beside [`FieldSource`] so that every crate's wrappers share it: here
//! [`crate::signed_density::SignedLogDensity`] (the baker's signed density),
//! `nelf-bake`'s `HullCarved` (that density carved to the masks' visual hull), and
//! `nelf-pipeline`'s `VoxelFiltered` (the network bake's box filter) and splits
//! (parts of one field swapped for another's).

use glam::{DMat3, Vec3};

use crate::field::{FieldError, FieldSource, ViewPolicy, evaluate_directions_one_by_one};

/// A field made from another ([`Adapter::base`]): its density, bounds and light
/// frame are the base's unless the adapter overrides them; its light transport is
/// its own ([`Adapter::evaluate`]). [`Adapted`] makes it a [`FieldSource`].
pub trait Adapter: Sync {
    /// The field this one rests on.
    fn base(&self) -> &dyn FieldSource;

    /// [`FieldSource::evaluate`]: what the adapter changes.
    fn evaluate(
        &self,
        points: &[Vec3],
        view: &ViewPolicy,
        density: &mut [f32],
        lt: &mut [f32],
    ) -> Result<(), FieldError>;

    /// [`FieldSource::evaluate_directions`]; by default [`Adapter::evaluate`] once
    /// per direction with [`ViewPolicy::Direction`], as `FieldSource`'s own default.
    fn evaluate_directions(
        &self,
        points: &[Vec3],
        directions: &[Vec3],
        density: &mut [f32],
        lt: &mut [f32],
    ) -> Result<(), FieldError> {
        evaluate_directions_one_by_one(points, directions, density, lt, |p, view, d, t| {
            self.evaluate(p, view, d, t)
        })
    }

    /// [`FieldSource::bounds`]; by default the base's.
    fn bounds(&self) -> (Vec3, Vec3) {
        self.base().bounds()
    }

    /// [`FieldSource::world_from_light`]; by default the base's.
    fn world_from_light(&self) -> DMat3 {
        self.base().world_from_light()
    }

    /// [`FieldSource::evaluate_density`]; by default the base's.
    fn evaluate_density(&self, points: &[Vec3], density: &mut [f32]) -> Result<(), FieldError> {
        self.base().evaluate_density(points, density)
    }
}

/// An [`Adapter`] as a [`FieldSource`] (what every adapter's constructor returns).
/// Dereferences to the adapter.
#[derive(Debug, Clone)]
pub struct Adapted<A>(pub A);

impl<A> std::ops::Deref for Adapted<A> {
    type Target = A;

    fn deref(&self) -> &A {
        &self.0
    }
}

impl<A: Adapter> FieldSource for Adapted<A> {
    fn evaluate(
        &self,
        points: &[Vec3],
        view: &ViewPolicy,
        density: &mut [f32],
        lt: &mut [f32],
    ) -> Result<(), FieldError> {
        self.0.evaluate(points, view, density, lt)
    }

    fn evaluate_directions(
        &self,
        points: &[Vec3],
        directions: &[Vec3],
        density: &mut [f32],
        lt: &mut [f32],
    ) -> Result<(), FieldError> {
        self.0.evaluate_directions(points, directions, density, lt)
    }

    fn bounds(&self) -> (Vec3, Vec3) {
        self.0.bounds()
    }

    fn world_from_light(&self) -> DMat3 {
        self.0.world_from_light()
    }

    fn evaluate_density(&self, points: &[Vec3], density: &mut [f32]) -> Result<(), FieldError> {
        self.0.evaluate_density(points, density)
    }
}
