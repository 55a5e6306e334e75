//! Camera input of the 3D view: the orbit camera around the asset ([`Orbit`]: framing,
//! orbit, pan, zoom) and the fingers on a touch screen ([`Fingers`]), and how one
//! frame's mouse, scroll and multi-touch input moves the orbit ([`Orbit::steer`]).

use eframe::egui;
use glam::DVec3;
use nelf_format::conventions::PinholeCamera;

use super::config::OrbitStart;

/// Orbit camera around a target.
#[derive(Debug, Clone, Copy)]
pub(super) struct Orbit {
    target: DVec3,
    yaw_rad: f64,
    pitch_rad: f64,
    distance_m: f64,
    fov_x_rad: f64,
}

impl Orbit {
    /// Frames a box: looks at its centre from +z (the front of a head).
    pub(super) fn framing(min: [f64; 3], max: [f64; 3]) -> Self {
        let lo = DVec3::from_array(min);
        let hi = DVec3::from_array(max);
        let radius = 0.5 * (hi - lo).length();
        let fov_x_rad = 40f64.to_radians();
        Self {
            target: 0.5 * (lo + hi),
            yaw_rad: 0.0,
            pitch_rad: 0.0,
            distance_m: (radius / (0.5 * fov_x_rad).sin()).max(1e-3),
            fov_x_rad,
        }
    }

    /// The framing of the box, turned and moved as `start` says.
    pub(super) fn started(min: [f64; 3], max: [f64; 3], start: OrbitStart) -> Self {
        let mut orbit = Self::framing(min, max);
        orbit.yaw_rad = start.azimuth_deg.to_radians();
        orbit.pitch_rad = start.elevation_deg.to_radians().clamp(-1.5, 1.5);
        if let Some(d) = start.distance_m.filter(|d| d.is_finite() && *d > 0.0) {
            orbit.distance_m = d;
        }
        orbit
    }

    fn eye(&self) -> DVec3 {
        let (sy, cy) = self.yaw_rad.sin_cos();
        let (sp, cp) = self.pitch_rad.sin_cos();
        self.target + self.distance_m * DVec3::new(cp * sy, sp, cp * cy)
    }

    pub(super) fn camera(&self, width: u32, height: u32) -> PinholeCamera {
        PinholeCamera::look_at(self.eye(), self.target, DVec3::Y, width, height, self.fov_x_rad)
    }

    /// Moves the target in the image plane by `(dx, dy)` points of a view `width` points wide.
    fn pan(&mut self, dx: f64, dy: f64, width: f64) {
        let forward = (self.target - self.eye()).normalize();
        let right = forward.cross(DVec3::Y).normalize();
        let up = right.cross(forward);
        let metres_per_point = 2.0 * self.distance_m * (0.5 * self.fov_x_rad).tan() / width.max(1.0);
        self.target += (-dx * right + dy * up) * metres_per_point;
    }

    /// Moves the orbit by one frame's input over the 3D view (`response` of its
    /// drag-sensing `rect`): a primary drag orbits, a secondary or middle drag (or a
    /// shift-drag) pans, two or more fingers pan, scroll and pinch zoom.
    /// `fingers_changed`: whether a finger landed or lifted this frame ([`Fingers::update`]).
    pub(super) fn steer(
        &mut self,
        ui: &egui::Ui,
        response: &egui::Response,
        rect: egui::Rect,
        fingers: &Fingers,
        fingers_changed: bool,
    ) {
        let shift = ui.input(|i| i.modifiers.shift);
        // The frame a drag starts moves nothing: with drags sensed from the press on, that
        // frame's pointer delta runs from wherever the pointer was before. Nor does a frame
        // where a finger landed or lifted (`Fingers`).
        let delta = if response.drag_started() || fingers_changed {
            egui::Vec2::ZERO
        } else {
            response.drag_delta()
        };
        if fingers.count() >= 2 {
            // Two or more fingers over the view pan (their mean translation) and
            // pinch-zoom (egui's zoom delta, below); the first finger, which egui also
            // reports as a dragging pointer, does not orbit meanwhile.
            let touch = ui
                .input(egui::InputState::multi_touch)
                .filter(|_| response.hovered());
            if let Some(touch) = touch {
                let pan = touch.translation_delta;
                self.pan(f64::from(pan.x), f64::from(pan.y), f64::from(rect.width()));
            }
        } else if response.dragged_by(egui::PointerButton::Primary) && !shift {
            self.yaw_rad -= f64::from(delta.x) * 0.01;
            self.pitch_rad = (self.pitch_rad + f64::from(delta.y) * 0.01).clamp(-1.5, 1.5);
        } else if response.dragged_by(egui::PointerButton::Secondary)
            || response.dragged_by(egui::PointerButton::Middle)
            || (response.dragged_by(egui::PointerButton::Primary) && shift)
        {
            self.pan(f64::from(delta.x), f64::from(delta.y), f64::from(rect.width()));
        }
        if response.hovered() {
            let scroll = ui.input(|i| i.smooth_scroll_delta.y);
            let zoom = ui.input(egui::InputState::zoom_delta);
            self.distance_m *= (-f64::from(scroll) * 0.002).exp() / f64::from(zoom.max(1e-3));
        }
    }
}

/// The fingers on a touch screen, counted from egui's own touch events. egui's
/// multi-touch state starts a frame after the second finger lands, and the pointer it
/// emulates from the fingers can jump from one finger to another as fingers come and go;
/// the 3D view orbits with one finger only, and moves nothing in a frame where a finger
/// landed or lifted.
#[derive(Debug, Default)]
pub(super) struct Fingers {
    down: std::collections::BTreeSet<egui::TouchId>,
}

impl Fingers {
    /// Takes one frame's input events; returns whether a finger landed or lifted.
    pub(super) fn update(&mut self, events: &[egui::Event]) -> bool {
        let mut changed = false;
        for event in events {
            if let egui::Event::Touch { id, phase, .. } = event {
                match phase {
                    egui::TouchPhase::Start => changed |= self.down.insert(*id),
                    egui::TouchPhase::End | egui::TouchPhase::Cancel => changed |= self.down.remove(id),
                    egui::TouchPhase::Move => {}
                }
            }
        }
        changed
    }

    pub(super) fn count(&self) -> usize {
        self.down.len()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fingers_are_counted_from_touch_events() {
        let touch = |id: u64, phase: egui::TouchPhase| egui::Event::Touch {
            device_id: egui::TouchDeviceId(0),
            id: egui::TouchId(id),
            phase,
            pos: egui::Pos2::ZERO,
            force: None,
        };
        let mut fingers = Fingers::default();
        assert!(!fingers.update(&[]));
        assert!(fingers.update(&[touch(7, egui::TouchPhase::Start)]));
        assert_eq!(fingers.count(), 1);
        assert!(!fingers.update(&[touch(7, egui::TouchPhase::Move)]));
        assert!(fingers.update(&[
            touch(8, egui::TouchPhase::Start),
            touch(7, egui::TouchPhase::Move)
        ]));
        assert_eq!(fingers.count(), 2);
        assert!(fingers.update(&[touch(7, egui::TouchPhase::Cancel)]));
        assert_eq!(fingers.count(), 1);
        // An end for a finger never seen (it landed outside the view) changes nothing.
        assert!(!fingers.update(&[touch(3, egui::TouchPhase::End)]));
        assert!(fingers.update(&[touch(8, egui::TouchPhase::End)]));
        assert_eq!(fingers.count(), 0);
    }

    #[test]
    fn orbit_frames_the_box_and_pans_in_the_image_plane() {
        let mut orbit = Orbit::framing([-0.1, -0.2, -0.1], [0.1, 0.2, 0.1]);
        let camera = orbit.camera(64, 64);
        camera.validate().unwrap();
        // Every corner of the box projects inside the image.
        for corner in 0..8 {
            let p = DVec3::new(
                if corner & 1 == 0 { -0.1 } else { 0.1 },
                if corner & 2 == 0 { -0.2 } else { 0.2 },
                if corner & 4 == 0 { -0.1 } else { 0.1 },
            );
            let px = camera.project(p).unwrap();
            assert!(
                (0.0..64.0).contains(&px.x) && (0.0..64.0).contains(&px.y),
                "{px:?}"
            );
        }
        // The camera starts in front (+z) and a pan right moves the target left in the world.
        assert!(camera.centre().z > 0.0);
        orbit.pan(10.0, 0.0, 64.0);
        assert!(orbit.target.x < 0.0);
    }
}
