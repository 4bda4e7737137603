"""What the ``clonedrive sim`` window draws: a 2D scene in pixels over its output.

Driving, it shows the center camera's image (the very image a recording stores, scaled up)
above a panel with the session's HUD lines, a steering bar and a REC badge; in the menu, the
menu's lines and a map of the chosen track with its start. Coordinates are pixels: x right from
the window's left edge, z up from its top edge (so z = -y_px).

Kept apart from the window (:mod:`clonedrive.manual.window`), which opens the output, reads
input and runs the loop: this module only turns a session's state into Panda3D nodes, and knows
nothing of where the frame goes.
"""

from __future__ import annotations

import numpy as np

from clonedrive.manual.hud import HELP_MENU
from clonedrive.manual.session import MENU, DrivingSession

#: The view's texture: a power of two in both directions, as the software renderer requires.
VIEW_TEXTURE = (512, 256)
FONT_PX = 19.0
SMALL_FONT_PX = 14.0
WHITE = (0.95, 0.95, 0.95, 1.0)
GREY = (0.65, 0.67, 0.7, 1.0)
RED = (1.0, 0.25, 0.2, 1.0)
CYAN = (0.35, 0.85, 1.0, 1.0)
YELLOW = (1.0, 0.85, 0.35, 1.0)
PANEL_RGB = (0.08, 0.09, 0.11)
#: The steering bar: half its length [px] (full lock), and its right end's margin [px].
BAR_HALF_PX = 220.0
BAR_MARGIN_PX = 30.0


class Overlay:
    """The window's 2D scene, built on ``output`` (a Panda3D window or buffer) of ``width`` x
    ``height`` pixels; :meth:`refresh` redraws it from a session, :meth:`remove` takes it down."""

    def __init__(self, output, width: int, height: int) -> None:
        from panda3d.core import Camera, NodePath, OrthographicLens, TransparencyAttrib

        self.width, self.height = width, height
        output.set_clear_color((*PANEL_RGB, 1.0))
        self.root = NodePath("overlay")
        self.root.set_depth_test(False)
        self.root.set_depth_write(False)
        self.root.set_transparency(TransparencyAttrib.M_alpha)
        lens = OrthographicLens()
        lens.set_film_size(width, height)
        lens.set_film_offset(width / 2, -height / 2)
        lens.set_near_far(-100, 100)
        camera = self.root.attach_new_node(Camera("overlay-camera", lens))
        output.make_display_region().set_camera(camera)
        self.view_height = width / 2  #: the camera view's height [px] (2:1, like the images)
        self.driving = self.root.attach_new_node("driving")
        self._build_view()
        self._build_steering_bar()
        self._build_hud_text()
        self._build_menu()
        self._map_track: str | None = None

    # ------------------------------------------------------------------ construction
    def _build_view(self) -> None:
        """The camera image's card, textured from a RAM image that :meth:`_show_image` fills."""
        from panda3d.core import SamplerState, Texture

        self._view_pixels = np.zeros((VIEW_TEXTURE[1], VIEW_TEXTURE[0], 3), np.uint8)
        texture = Texture("camera-view")
        texture.setup_2d_texture(*VIEW_TEXTURE, Texture.T_unsigned_byte, Texture.F_rgb)
        texture.set_minfilter(SamplerState.FT_linear)
        texture.set_magfilter(SamplerState.FT_linear)
        texture.set_wrap_u(SamplerState.WM_clamp)
        texture.set_wrap_v(SamplerState.WM_clamp)
        texture.set_ram_image(self._view_pixels.tobytes())
        self._view_texture = texture
        self.view = card(self.driving, "view", 0, self.width, -self.view_height, 0)
        self.view.set_texture(texture)
        self.view.set_bin("fixed", 0)

    def _build_steering_bar(self) -> None:
        """A track and a marker from its centre to the applied steering."""
        from panda3d.core import CardMaker

        bar_z = -self.view_height - 12
        self._bar_centre_px = self.width - BAR_MARGIN_PX - BAR_HALF_PX
        left, right = self._bar_centre_px - BAR_HALF_PX, self._bar_centre_px + BAR_HALF_PX
        track = card(self.driving, "steering-track", left, right, bar_z - 4, bar_z + 4)
        track.set_color(0.25, 0.27, 0.3, 1)
        track.set_bin("fixed", 1)
        centre = card(self.driving, "steering-zero", self._bar_centre_px - 1,
                      self._bar_centre_px + 1, bar_z - 7, bar_z + 7)
        centre.set_color(*GREY)
        centre.set_bin("fixed", 3)
        cards = CardMaker("steering-marker")
        cards.set_frame(0, 1, bar_z - 4, bar_z + 4)
        self.steering_marker = self.driving.attach_new_node(cards.generate())
        self.steering_marker.set_color(*CYAN)
        self.steering_marker.set_bin("fixed", 2)

    def _build_hud_text(self) -> None:
        """The HUD's lines under the view, the help line at the bottom, the REC badge."""
        left, line_px = 14.0, 1.3 * FONT_PX
        first_line = -self.view_height - 26 - FONT_PX
        driving = self.driving
        self.status_text = text(driving, "status", left, first_line, FONT_PX, WHITE)
        self.mode_text = text(driving, "mode", left, first_line - line_px, FONT_PX, CYAN)
        self.recording_text = text(driving, "recording", left, first_line - 2 * line_px,
                                   FONT_PX, WHITE)
        self.message_text = text(driving, "message", left, first_line - 3 * line_px,
                                 SMALL_FONT_PX, YELLOW)
        self.help_text = text(driving, "help", left, -self.height + 9, SMALL_FONT_PX, GREY)
        self.rec_badge = text(driving, "rec-badge", self.width - 16, -16 - 26, 26.0, RED,
                              align_right=True)
        self.rec_badge.node().set_text("REC")
        for node in (self.status_text, self.mode_text, self.recording_text, self.message_text,
                     self.help_text, self.rec_badge):
            node.set_bin("fixed", 10)

    def _build_menu(self) -> None:
        width, height = self.width, self.height
        self.menu = self.root.attach_new_node("menu")
        self.menu_text = text(self.menu, "menu", 48, -70, 26.0, WHITE)
        self.menu_help = text(self.menu, "menu-help", 48, -height + 16, SMALL_FONT_PX, GREY)
        self.map_node = self.menu.attach_new_node("map")
        self.map_text = text(self.menu, "map-text", width * 0.55, -height + 60, SMALL_FONT_PX,
                             GREY)
        self.loading_text = text(self.root, "loading", width / 2 - 120, -height / 2, 28.0,
                                 YELLOW)

    # ------------------------------------------------------------------ drawing
    def refresh(self, session: DrivingSession) -> None:
        """Update the view and the text from the session's state."""
        loading = session.loading
        self.loading_text.node().set_text(session.message if loading else "")
        in_menu = session.mode == MENU and not loading
        if in_menu or loading:
            self.driving.hide()
            if in_menu:
                self.menu.show()
            else:
                self.menu.hide()
            self._refresh_menu(session)
            return
        self.menu.hide()
        self.driving.show()
        obs = session.observation
        image = obs.images.get("center") if obs is not None else None
        if image is not None:
            self._show_image(image)
        self._refresh_hud(session)

    def _refresh_hud(self, session: DrivingSession) -> None:
        hud = session.hud()
        self.status_text.node().set_text(hud.status)
        self.mode_text.node().set_text(hud.mode)
        self.recording_text.node().set_text(hud.recording)
        self.recording_text.node().set_text_color(*(RED if session.recording else WHITE))
        self.message_text.node().set_text(hud.message)
        self.help_text.node().set_text(hud.help)
        if session.recording:
            self.rec_badge.show()
        else:
            self.rec_badge.hide()
        steering = float(session.controls.steering)
        length = max(abs(steering) * BAR_HALF_PX, 0.5)
        start = self._bar_centre_px + min(steering, 0.0) * BAR_HALF_PX
        self.steering_marker.set_pos(start, 0, 0)
        self.steering_marker.set_sx(length)

    def _show_image(self, image_rgb: np.ndarray) -> None:
        import cv2

        width, height = VIEW_TEXTURE
        scaled = cv2.resize(image_rgb, (width, height), interpolation=cv2.INTER_LINEAR)
        self._view_pixels[:] = scaled[::-1]  # Panda3D's textures start at the bottom row
        self._view_texture.set_ram_image_as(self._view_pixels.tobytes(), "RGB")

    def _refresh_menu(self, session: DrivingSession) -> None:
        self.menu_text.node().set_text("\n".join(session.menu_lines()))
        self.menu_help.node().set_text(HELP_MENU)
        item = session.menu_items[session.menu_index].track
        if item != self._map_track:
            self._draw_map(item)

    def _draw_map(self, track_name: str) -> None:
        """The chosen track's outline, fitted into the menu's right half, with the start."""
        from panda3d.core import LineSegs

        from clonedrive.world.catalog import load_track
        from clonedrive.world.track import TrackError

        self._map_track = track_name
        self.map_node.node().remove_all_children()
        try:
            track = load_track(track_name)
        except (TrackError, OSError) as error:
            self.map_text.node().set_text(str(error))
            return
        self.map_text.node().set_text(
            f"{track.name}: {track.length_m:.0f} m, road {float(track.width.mean()):.1f} m "
            f"wide, tightest radius {track.min_radius_m:.0f} m, climbs "
            f"{track.elevation_range_m:.0f} m\nred square: the start")
        xy = track.xyz[:, :2]
        low, high = xy.min(axis=0), xy.max(axis=0)
        box_left, box_top, box_size = self.width * 0.55, -90.0, min(self.width * 0.4, 400.0)
        scale = box_size / max(float((high - low).max()), 1.0)
        points = (xy - (low + high) / 2) * scale
        lines = LineSegs("outline")
        lines.set_thickness(3.0)
        lines.set_color(0.75, 0.78, 0.8, 1)
        x0, z0 = box_left + box_size / 2, box_top - box_size / 2
        lines.move_to(x0 + points[0, 0], 0, z0 + points[0, 1])
        for x, y in points[1::4]:
            lines.draw_to(x0 + x, 0, z0 + y)
        lines.draw_to(x0 + points[0, 0], 0, z0 + points[0, 1])
        self.map_node.attach_new_node(lines.create())
        start_x, start_z = x0 + points[0, 0], z0 + points[0, 1]
        start = card(self.map_node, "start", start_x - 5, start_x + 5, start_z - 5, start_z + 5)
        start.set_color(*RED)

    def remove(self) -> None:
        self.root.remove_node()


def card(parent, name: str, left: float, right: float, bottom: float, top: float):
    """A flat rectangle [px] under ``parent``."""
    from panda3d.core import CardMaker

    maker = CardMaker(name)
    maker.set_frame(left, right, bottom, top)
    return parent.attach_new_node(maker.generate())


def text(parent, name: str, x_px: float, z_px: float, size_px: float, colour,
         *, align_right: bool = False):
    """A text node with its baseline's left (or right) end at (x, z) [px]."""
    from panda3d.core import TextNode

    node = TextNode(name)
    node.set_text_color(*colour)
    node.set_shadow(0.06, 0.06)
    node.set_shadow_color(0, 0, 0, 0.9)
    if align_right:
        node.set_align(TextNode.A_right)
    path = parent.attach_new_node(node)
    path.set_pos(x_px, 0, z_px)
    path.set_scale(size_px)
    return path
