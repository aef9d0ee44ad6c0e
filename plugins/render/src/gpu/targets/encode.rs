//! Recording a frame: geometry upload, the shadow pass, and per camera the opaque, marker and
//! overlay passes and the readback copies ([`Targets::encode`]).

use nalgebra::{Matrix4, Vector3};

use crate::geometry::FrameGeometry;

use super::{columns, grow_buffer, projection, Targets, ViewSetup, ViewUniform};

impl Targets {
    /// Uploads `geom` and records the shadow pass and, per `(slot, view)`, the camera passes and
    /// readback copies (`readback = false`: render only, e.g. for a window).
    pub(crate) fn encode(
        &mut self,
        encoder: &mut wgpu::CommandEncoder,
        geom: &FrameGeometry,
        views: &[(usize, ViewSetup)],
        readback: bool,
    ) {
        self.fit_shadow_map(views);
        for (slot, _) in views {
            if self.cameras[*slot].1.bind.0 != self.generation {
                let bind = self.camera_bind(&self.cameras[*slot].1.uniform);
                self.cameras[*slot].1.bind = (self.generation, bind);
            }
        }
        let dev = self.device.clone();
        let (d, q) = (&dev.device, &dev.queue);
        let vbytes: &[u8] = bytemuck::cast_slice(&geom.vertices);
        let ibytes: &[u8] = bytemuck::cast_slice(&geom.indices);
        grow_buffer(
            d,
            &mut self.vertices,
            vbytes.len() as u64,
            wgpu::BufferUsages::VERTEX,
        );
        grow_buffer(
            d,
            &mut self.indices,
            ibytes.len() as u64,
            wgpu::BufferUsages::INDEX,
        );
        let (Some((vb, _)), Some((ib, _))) = (&self.vertices, &self.indices) else {
            return;
        };
        if !vbytes.is_empty() {
            q.write_buffer(vb, 0, vbytes);
        }
        if !ibytes.is_empty() {
            q.write_buffer(ib, 0, ibytes);
        }
        let shadows = self.shadow.size > 1;
        let (light_vp, r) = self.light_view_proj(geom);
        let texel_world = 2.0 * r / self.shadow.size as f64;
        let light_dir = Vector3::from(self.light.direction).normalize();
        let mut uniform = ViewUniform {
            view_proj: columns(&Matrix4::identity()),
            light_view_proj: columns(&light_vp),
            cam_pos: [0.0; 4],
            cam_fwd: [0.0, 0.0, 1.0, 0.0],
            light_dir: [
                light_dir.x as f32,
                light_dir.y as f32,
                light_dir.z as f32,
                self.light.ambient,
            ],
            params: [
                if shadows { 1.0 } else { 0.0 },
                1.0 / self.shadow.size as f32,
                (1.5 * texel_world) as f32,
                (0.5 / self.shadow.size as f64) as f32,
            ],
        };
        let opaque = 0..geom.opaque_indices;
        let target_range = geom.opaque_indices..geom.target_indices;
        let overlay_range = geom.target_indices..geom.indices.len() as u32;
        if shadows {
            q.write_buffer(&self.shadow.uniform, 0, bytemuck::bytes_of(&uniform));
            let mut pass = encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
                label: Some("shadow"),
                color_attachments: &[],
                depth_stencil_attachment: Some(wgpu::RenderPassDepthStencilAttachment {
                    view: &self.shadow.view,
                    depth_ops: Some(wgpu::Operations {
                        load: wgpu::LoadOp::Clear(1.0),
                        store: wgpu::StoreOp::Store,
                    }),
                    stencil_ops: None,
                }),
                ..Default::default()
            });
            if !opaque.is_empty() {
                pass.set_pipeline(&dev.pipelines.shadow);
                pass.set_bind_group(0, &self.shadow.bind, &[]);
                pass.set_vertex_buffer(0, vb.slice(..));
                pass.set_index_buffer(ib.slice(..), wgpu::IndexFormat::Uint32);
                pass.draw_indexed(opaque.clone(), 0, 0..1);
            }
        }
        let bg = self.background.map(|x| x as f64);
        for (slot, view) in views {
            let t = &mut self.cameras[*slot].1;
            t.last = Some(*view);
            let p = projection(t.width, t.height, view.pinhole, view.near, view.far);
            let vp = p * view.world_from_camera.inverse().to_homogeneous();
            let pos = view.world_from_camera.translation.vector;
            let fwd = view.world_from_camera.rotation * Vector3::z();
            uniform.view_proj = columns(&vp);
            uniform.cam_pos = [pos.x as f32, pos.y as f32, pos.z as f32, 1.0];
            uniform.cam_fwd = [fwd.x as f32, fwd.y as f32, fwd.z as f32, 0.0];
            q.write_buffer(&t.uniform, 0, bytemuck::bytes_of(&uniform));
            {
                let mut pass = encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
                    label: Some("camera"),
                    color_attachments: &[
                        Some(wgpu::RenderPassColorAttachment {
                            view: &t.color_view,
                            depth_slice: None,
                            resolve_target: None,
                            ops: wgpu::Operations {
                                load: wgpu::LoadOp::Clear(wgpu::Color {
                                    r: bg[0],
                                    g: bg[1],
                                    b: bg[2],
                                    a: 1.0,
                                }),
                                store: wgpu::StoreOp::Store,
                            },
                        }),
                        Some(wgpu::RenderPassColorAttachment {
                            view: &t.data_view,
                            depth_slice: None,
                            resolve_target: None,
                            ops: wgpu::Operations {
                                load: wgpu::LoadOp::Clear(wgpu::Color::TRANSPARENT),
                                store: wgpu::StoreOp::Store,
                            },
                        }),
                    ],
                    depth_stencil_attachment: Some(wgpu::RenderPassDepthStencilAttachment {
                        view: &t.depth_view,
                        depth_ops: Some(wgpu::Operations {
                            load: wgpu::LoadOp::Clear(1.0),
                            store: wgpu::StoreOp::Store,
                        }),
                        stencil_ops: None,
                    }),
                    ..Default::default()
                });
                if !opaque.is_empty() {
                    pass.set_pipeline(&dev.pipelines.opaque);
                    pass.set_bind_group(0, &t.bind.1, &[]);
                    pass.set_vertex_buffer(0, vb.slice(..));
                    pass.set_index_buffer(ib.slice(..), wgpu::IndexFormat::Uint32);
                    pass.draw_indexed(opaque.clone(), 0, 0..1);
                }
            }
            let ranges = [
                (view.markers, &target_range),
                (view.overlays, &overlay_range),
            ];
            if ranges.iter().any(|(on, r)| *on && !r.is_empty()) {
                let mut pass = encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
                    label: Some("markers"),
                    color_attachments: &[Some(wgpu::RenderPassColorAttachment {
                        view: &t.color_view,
                        depth_slice: None,
                        resolve_target: None,
                        ops: wgpu::Operations {
                            load: wgpu::LoadOp::Load,
                            store: wgpu::StoreOp::Store,
                        },
                    })],
                    depth_stencil_attachment: Some(wgpu::RenderPassDepthStencilAttachment {
                        view: &t.depth_view,
                        depth_ops: Some(wgpu::Operations {
                            load: wgpu::LoadOp::Load,
                            store: wgpu::StoreOp::Store,
                        }),
                        stencil_ops: None,
                    }),
                    ..Default::default()
                });
                pass.set_bind_group(0, &t.bind.1, &[]);
                pass.set_vertex_buffer(0, vb.slice(..));
                pass.set_index_buffer(ib.slice(..), wgpu::IndexFormat::Uint32);
                let pipelines = [&dev.pipelines.markers, &dev.pipelines.overlays];
                for ((on, r), pipeline) in ranges.iter().zip(pipelines) {
                    if *on && !r.is_empty() {
                        pass.set_pipeline(pipeline);
                        pass.draw_indexed((*r).clone(), 0, 0..1);
                    }
                }
            }
            if readback {
                let size = wgpu::Extent3d {
                    width: t.width,
                    height: t.height,
                    depth_or_array_layers: 1,
                };
                for (tex, offset, row) in [
                    (&t.color, 0, t.color_row),
                    (&t.data, t.data_offset, t.data_row),
                ] {
                    encoder.copy_texture_to_buffer(
                        tex.as_image_copy(),
                        wgpu::TexelCopyBufferInfo {
                            buffer: &t.readback,
                            layout: wgpu::TexelCopyBufferLayout {
                                offset,
                                bytes_per_row: Some(row),
                                rows_per_image: Some(t.height),
                            },
                        },
                        size,
                    );
                }
            }
        }
    }
}
