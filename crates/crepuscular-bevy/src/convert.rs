//! Bevy's lights and shadow views as the library's `FrameLight`s (docs/BEVY.md).

use bevy::camera::visibility::RenderLayers;
use bevy::pbr::{
    ExtractedDirectionalLight, ExtractedPointLight, GlobalClusterableObjectMeta, MAX_CASCADES_PER_LIGHT,
    MAX_DIRECTIONAL_LIGHTS, PointAndSpotLightViewEntities,
};
use bevy::prelude::*;
use bevy::render::view::ExtractedView;
use crepuscular::{DepthConvention, FrameLight, Light, ShadowProjection};

use crate::shadow_copy::{CopyJobs, Job};
use crate::{CascadeChoice, CrepuscularGobo, CrepuscularLight, to_glam_mat};
use std::sync::Arc;

/// A Bevy (glam 0.32) vector as the library's (glam 0.30).
pub fn to_glam(v: Vec3) -> glam::Vec3 {
    glam::Vec3::new(v.x, v.y, v.z)
}

/// Bevy's spot and point shadow projections are infinite (reversed-Z, depth = near / z). The
/// library linearises a perspective map with a finite far plane F: z = n·F / (n + d·(F − n)).
/// With F = n·10⁷ that is Bevy's n / d to a relative 10⁻⁷·z/n — and the stored depth and the
/// sample's own depth go through the same map, so the comparison itself is exact.
const INFINITE_FAR_OVER_NEAR: f32 = 1.0e7;

/// The largest spot cone the library takes (its `outer_angle_degrees` is in (0, 89]).
const MAX_SPOT_DEGREES: f32 = 89.0;

pub(crate) type DirectionalItem<'a> =
    (Entity, &'a ExtractedDirectionalLight, Option<&'a RenderLayers>, Option<&'a CrepuscularLight>);
pub(crate) type PointItem<'a> = (
    Entity,
    &'a ExtractedPointLight,
    &'a PointAndSpotLightViewEntities,
    Option<&'a CrepuscularLight>,
    Option<&'a CrepuscularGobo>,
);

/// What the conversion needs to know of the view.
pub(crate) struct LightsInView {
    pub view: Entity,
    pub view_layers: RenderLayers,
    pub cascade: CascadeChoice,
    /// The camera's exposure (Bevy multiplies every light by it before writing HDR colour).
    pub exposure: f32,
    /// Side of Bevy's directional/spot shadow texture, texels.
    pub directional_size: u32,
    /// Side of Bevy's point-light cube texture, texels.
    pub point_size: u32,
}

fn rgb(c: LinearRgba) -> glam::Vec3 {
    glam::Vec3::new(c.red, c.green, c.blue)
}

fn view_proj(v: &ExtractedView) -> Mat4 {
    v.clip_from_world.unwrap_or_else(|| v.clip_from_view * v.world_from_view.to_matrix().inverse())
}

impl LightsInView {
    /// The marked lights of the view, in the order Bevy assigns their shadow layers, the
    /// copies that gather their maps into the plugin's array, and the spots' gobos (light
    /// `texture_layer` i is gobo i).
    pub fn collect(
        &self,
        directional: &[DirectionalItem],
        points: &[PointItem],
        shadow_views: &Query<&ExtractedView>,
        meta: Option<&GlobalClusterableObjectMeta>,
    ) -> Result<(Vec<FrameLight>, CopyJobs, Vec<Arc<crepuscular::RgbTexture>>), String> {
        let mut lights = Vec::new();
        let mut gobos: Vec<Arc<crepuscular::RgbTexture>> = Vec::new();
        let mut jobs = CopyJobs::default();
        let mut next_layer = 0u32;
        let mut dir_size = 0u32;
        let mut point_size = 0u32;

        // Directional lights: Bevy sorts them by (volumetric, shadows enabled, entity) and gives
        // each shadowed light's cascades consecutive layers of the directional texture, from 0,
        // for the lights on the view's render layers (bevy_pbr prepare_lights).
        let mut dirs: Vec<&DirectionalItem> =
            directional.iter().filter(|d| d.2.cloned().unwrap_or_default().intersects(&self.view_layers)).collect();
        dirs.sort_by_key(|d| (d.1.volumetric, d.1.shadow_maps_enabled, d.0));
        let mut base = 0u32;
        for d in dirs.into_iter().take(MAX_DIRECTIONAL_LIGHTS) {
            let (entity, light, _, marker) = *d;
            let count = if light.shadow_maps_enabled {
                light.cascade_shadow_config.bounds.len().min(MAX_CASCADES_PER_LIGHT) as u32
            } else {
                0
            };
            if let Some(marker) = marker {
                if count == 0 {
                    return Err(format!("directional light {entity} has CrepuscularLight but no shadow maps"));
                }
                let cascades = light
                    .cascades
                    .get(&self.view)
                    .ok_or_else(|| format!("directional light {entity} has no cascades for this view yet"))?;
                let n = cascades.len().min(count as usize);
                if n == 0 {
                    return Err(format!("directional light {entity} has no cascades for this view yet"));
                }
                let k = match self.cascade {
                    CascadeChoice::Farthest => n - 1,
                    CascadeChoice::Index(i) => i.min(n - 1),
                };
                let c = &cascades[k];
                // Reversed-Z orthographic: ndc z = 1 at the cascade's near plane (the origin of
                // world_from_cascade), 0 at 1/r behind it (bevy_light cascade.rs).
                let r = c.clip_from_cascade.z_axis.z;
                if !(r.is_finite() && r > 0.0) {
                    return Err(format!("directional light {entity}: cascade {k} has depth scale {r}"));
                }
                let mut view_proj = [glam::Mat4::IDENTITY; 6];
                view_proj[0] = to_glam_mat(c.clip_from_world);
                let shadow = ShadowProjection {
                    view_proj,
                    layers: 1,
                    near: 0.0,
                    far: 1.0 / r,
                    orthographic: true,
                    size: self.directional_size,
                    texel_world: c.texel_size,
                    depth: DepthConvention::Reversed,
                };
                let l = Light::Directional {
                    direction: to_glam(light.transform.forward().into()),
                    color: rgb(light.color),
                    intensity: light.illuminance * self.exposure,
                };
                lights.push(self.frame_light(l, shadow, marker, next_layer));
                jobs.directional.push(Job {
                    src_layer: base + k as u32,
                    dst_layer: next_layer,
                    size: self.directional_size,
                    _pad: 0,
                });
                dir_size = self.directional_size;
                next_layer += 1;
            }
            base += count;
        }
        // Spot maps follow all the cascades in the same texture; point lights' six faces are
        // layers 6i..6i+6 of the cube texture, i the light's clustered index (point lights
        // first, then spots: a spot's map is layer cascades + (index − point lights)).
        let any_marked = points.iter().any(|p| p.3.is_some());
        if any_marked {
            let meta = meta.ok_or("Bevy's clustered-light table is missing")?;
            let point_count = points.iter().filter(|p| p.1.spot_light_angles.is_none()).count();
            for &(entity, light, views, marker, gobo) in points {
                let Some(marker) = marker else { continue };
                if !light.shadow_maps_enabled {
                    return Err(format!("light {entity} has CrepuscularLight but no shadow maps"));
                }
                let index = *meta
                    .entity_to_index
                    .get(&entity)
                    .ok_or_else(|| format!("light {entity} is not in Bevy's clustered-light table"))?;
                let near = light.shadow_map_near_z;
                let position = to_glam(light.transform.translation());
                let color = rgb(light.color);
                let intensity = light.intensity * self.exposure;
                match light.spot_light_angles {
                    Some((inner, outer)) => {
                        let view = views.first().and_then(|e| shadow_views.get(*e).ok());
                        let view = view.ok_or_else(|| format!("spot light {entity} has no shadow view yet"))?;
                        let outer_deg = outer.to_degrees().min(MAX_SPOT_DEGREES);
                        let mut view_proj = [glam::Mat4::IDENTITY; 6];
                        view_proj[0] = to_glam_mat(view_proj_of(view));
                        let shadow = ShadowProjection {
                            view_proj,
                            layers: 1,
                            near,
                            far: near * INFINITE_FAR_OVER_NEAR,
                            orthographic: false,
                            size: self.directional_size,
                            texel_world: 2.0 * outer.min(MAX_SPOT_DEGREES.to_radians()).tan()
                                / self.directional_size as f32,
                            depth: DepthConvention::Reversed,
                        };
                        let l = Light::Spot {
                            position,
                            direction: to_glam(light.transform.forward().into()),
                            outer_angle_degrees: outer_deg,
                            inner_angle_degrees: inner.to_degrees().min(outer_deg),
                            color,
                            intensity,
                            texture: gobo.map(|g| g.texture.clone()),
                        };
                        let src = base + (index - point_count.min(index)) as u32;
                        let mut fl = self.frame_light(l, shadow, marker, next_layer);
                        if let Some(g) = gobo {
                            fl.texture_layer = gobos.len() as u32;
                            gobos.push(g.texture.clone());
                        }
                        lights.push(fl);
                        jobs.directional.push(Job {
                            src_layer: src,
                            dst_layer: next_layer,
                            size: self.directional_size,
                            _pad: 0,
                        });
                        dir_size = self.directional_size;
                        next_layer += 1;
                    }
                    None => {
                        if views.len() != 6 {
                            return Err(format!("point light {entity} has {} shadow views, not 6", views.len()));
                        }
                        // Bevy's face order need not be the library's (+X −X +Y −Y +Z −Z): each
                        // face goes to the layer of the axis it looks along.
                        let mut view_proj = [glam::Mat4::IDENTITY; 6];
                        let mut seen = [false; 6];
                        for (face, e) in views.iter().enumerate() {
                            let v = shadow_views
                                .get(*e)
                                .map_err(|_| format!("point light {entity}: face {face} has no view"))?;
                            let forward = to_glam(v.world_from_view.forward().into());
                            let slot = crepuscular::shadow::cube_face(forward) as usize;
                            if seen[slot] {
                                return Err(format!("point light {entity}: two faces look along axis {slot}"));
                            }
                            seen[slot] = true;
                            view_proj[slot] = to_glam_mat(view_proj_of(v));
                            jobs.point.push(Job {
                                src_layer: (index * 6 + face) as u32,
                                dst_layer: next_layer + slot as u32,
                                size: self.point_size,
                                _pad: 0,
                            });
                        }
                        let shadow = ShadowProjection {
                            view_proj,
                            layers: 6,
                            near,
                            far: near * INFINITE_FAR_OVER_NEAR,
                            orthographic: false,
                            size: self.point_size,
                            texel_world: 2.0 / self.point_size as f32,
                            depth: DepthConvention::Reversed,
                        };
                        let l = Light::Point { position, color, intensity };
                        lights.push(self.frame_light(l, shadow, marker, next_layer));
                        point_size = self.point_size;
                        next_layer += 6;
                    }
                }
            }
        }
        jobs.layers = next_layer;
        jobs.size = dir_size.max(point_size);
        Ok((lights, jobs, gobos))
    }

    fn frame_light(&self, light: Light, shadow: ShadowProjection, marker: &CrepuscularLight, layer: u32) -> FrameLight {
        let mut fl = FrameLight::new(light, shadow);
        fl.shadow_layer = layer;
        fl.scattering = marker.scattering;
        fl.shadow_bias = marker.shadow_bias;
        fl.shadow_filter = marker.shadow_filter;
        fl
    }
}

fn view_proj_of(v: &ExtractedView) -> Mat4 {
    view_proj(v)
}
